"""The Streamlit app, shipped with the package: ``gesturekit app`` serves it.

:data:`HOME` is its entrypoint script; the pages are scripts in ``views/``
(declared in :mod:`gesturekit.app.nav`). From a clone, ``streamlit run
app/Home.py`` serves the same app. Importing this package does not import
Streamlit, so the command line can find the app without it.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["APP_DIR", "HOME"]

#: The folder of the app's scripts, inside the installed package.
APP_DIR = Path(__file__).resolve().parent
#: The entrypoint script Streamlit runs (``streamlit run`` or ``gesturekit app``).
HOME = APP_DIR / "Home.py"
