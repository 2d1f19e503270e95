"""gesturekit's app: start it with ``gesturekit app`` (from a clone, also ``streamlit run app/Home.py``).

This file is the entrypoint: each page view runs it as ``__main__``, and it
draws the page the user is on (the pages are declared in :mod:`gesturekit.app.nav`); the
home page is :func:`home` below. On a machine without a database, every page
builds the generated demo speaker's database at the default path first, with
a progress bar; nothing is downloaded.

``streamlit run`` finds the ``st.App`` below and serves the pages through it:
its lifespan prepares the default database's search and refiner as the server
starts (:func:`resources.server_lifespan`), so the first run does not wait for
them.
"""

import streamlit as st

from gesturekit.app import nav, resources, sidebar
from gesturekit.app.display import escape_markdown
from gesturekit.workspace import database_words


def home() -> None:
    st.title("gesturekit")
    st.markdown(
        "Speech in, co-speech gestures out, by **motion matching**: the method of Habibie et al., "
        "*A Motion Matching-based Framework for Controllable Gesture Synthesis from Speech* (SIGGRAPH 2022).\n\n"
        "A database of recorded motion with its speech is cut into short clips. For new speech, the search "
        "steps through time, 8 frames at a step, and at each step picks the database segment whose speech "
        "matches the coming second of the new speech and whose pose continues the motion so far. Controls "
        "(hands high or low, fast or slow, wide, symmetric...) restrict, for stretches of time, which database "
        "frames may be used. An optional conditional GAN refines the result into smooth motion."
    )
    db = sidebar.sidebar_database()
    resources.warm_up(db)  # a database chosen here is prepared while the user moves on

    st.subheader("Open database")
    sidebar.show_database_label(db)
    d = db.describe()
    said = database_words(d["path"])  # in words: the server's folder is not shown
    st.markdown(
        f"{escape_markdown(said[:1].upper() + said[1:])}: {d['takes']} takes, "
        f"{d['clips']} clips of {d['clip_frames']} frames "
        f"({d['minutes_in_clips']:.1f} minutes at {d['fps']} fps), "
        f"{'with' if d['has_audio'] else 'without'} audio. Source: {escape_markdown(d['source'] or 'unknown')}."
    )
    st.caption("Choose another database, or build one from a folder of takes, in the sidebar.")

    st.subheader("Pages")
    for page in nav.PAGES:
        nav.link(page.title)
        st.caption(page.purpose)


if __name__ == "__main__":
    nav.run(home)
else:  # imported by the server at start
    app = st.App(__file__, lifespan=resources.server_lifespan)
