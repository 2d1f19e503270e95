"""The viewer's web module: JavaScript sources (``src/``) bundled with three.js from the npm registry by
:mod:`gesturekit.viz.web.build` into ``static/``."""
