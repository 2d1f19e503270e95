"""Start Streamlit's server on the packaged app: what ``gesturekit app`` runs once its options are read.

The command line's part (:mod:`gesturekit.cli._app`) never imports Streamlit; this
module hands its arguments to Streamlit's own command line, which reads the
configuration, finds the entrypoint's ``st.App`` and serves it until interrupted.
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["serve"]


def serve(argv: Sequence[str]) -> int:
    """Run ``streamlit ARGV`` in this process (``["run", HOME, "--server.port", "8501", ...]``).

    Returns
    -------
    int
        The exit status Streamlit's command line ends with (0 when the server was stopped).
    """
    from streamlit.web import cli as streamlit_cli

    try:
        streamlit_cli.main(args=list(argv), prog_name="streamlit", standalone_mode=True)
    except SystemExit as stop:  # click ends every command this way
        return stop.code if isinstance(stop.code, int) else (0 if stop.code is None else 1)
    return 0
