"""gesturekit's app from a clone: ``streamlit run app/Home.py`` serves the app the package ships.

The app lives in :mod:`gesturekit.app` (``gesturekit/app/Home.py`` and its pages), so that an
install from a wheel has it too (``gesturekit app``). This script only hands Streamlit that
entrypoint: the server serves its ``st.App``; run as a page script, it runs it.
"""

import runpy

import streamlit as st

from gesturekit.app import HOME

if __name__ == "__main__":
    runpy.run_path(str(HOME), run_name="__main__")
else:  # imported by the server at start: serve the packaged entrypoint, with its lifespan
    from gesturekit.app.resources import server_lifespan

    app = st.App(HOME, lifespan=server_lifespan)
