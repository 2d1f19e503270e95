"""``gesturekit app``: serve the Streamlit app the package ships (:mod:`gesturekit.app`).

The app's safe settings travel as Streamlit flags, so they hold from any working
directory (Streamlit reads ``.streamlit/config.toml`` only from the one it starts in):
this machine only unless ``--address`` says otherwise, no usage statistics, uploads
capped, the viewer's toolbar without the developer menu, error details kept in the
server's log. The folders the app may read and write are gesturekit's home,
``./db`` and ``$GESTUREKIT_APP_ROOTS``; ``--allow`` adds to the last.
"""

from __future__ import annotations

import argparse
import importlib.util
import ipaddress
import os
from pathlib import Path

from ..errors import ConfigError, MissingDependencyError
from ..paths import APP_ROOTS_ENV

__all__ = ["ABOUT", "APP_FLAGS", "add_app_parser", "app_roots", "streamlit_args", "run"]

#: The command's line in ``gesturekit --help`` and the paragraph of its own ``--help``.
ABOUT = (
    "serve the app (Streamlit) on this machine: synthesis, the retrieval inspector, databases, studies",
    "Serve gesturekit's Streamlit app. It listens on 127.0.0.1 (this machine only) unless --address says "
    "otherwise; the folders it may read and write are gesturekit's home (GESTUREKIT_HOME), ./db and those "
    f"in {APP_ROOTS_ENV}, with --allow adding more. Stop it with Ctrl+C.",
)

#: Streamlit's settings for the app, whatever the working directory: the values of the
#: repository's ``.streamlit/config.toml`` (a clone's ``streamlit run app/Home.py``), and no
#: usage statistics, no browser opened, no e-mail prompt at the first start and no watching
#: of the installed scripts for changes.
APP_FLAGS: dict[str, str] = {
    "server.maxUploadSize": "200",  # megabytes per file: an hour of compressed speech
    "client.toolbarMode": "viewer",  # no Deploy button, no developer menu
    "client.showErrorDetails": "none",  # an uncaught error's details go to the server's log only
    "browser.gatherUsageStats": "false",
    "server.headless": "true",
    "server.fileWatcherType": "none",  # the installed scripts do not change while it runs
}


def add_app_parser(p: argparse.ArgumentParser) -> None:
    """The options of ``gesturekit app``."""
    p.add_argument(
        "--address",
        "--host",
        default="127.0.0.1",
        help="address to listen on (default 127.0.0.1: this machine only; 0.0.0.0 serves every network, "
        "see the app guide's 'Serving the app to others')",
    )
    p.add_argument("--port", type=int, default=8501, help="port (default 8501)")
    p.add_argument(
        "--search-device",
        metavar="DEVICE",
        help="scan the database on this torch device (cuda, cuda:1) in every synthesis: the same motion, for "
        "large databases (default: $GESTUREKIT_SEARCH_DEVICE if set, else the CPU)",
    )
    p.add_argument(
        "--allow",
        action="append",
        default=[],
        metavar="FOLDER",
        help=f"a folder the app may also read and write (repeat for more; added to {APP_ROOTS_ENV})",
    )


def app_roots(allow: list[str], environ: dict[str, str] | os._Environ) -> str:
    """``$GESTUREKIT_APP_ROOTS`` with the ``--allow`` folders added, as absolute paths.

    Raises
    ------
    ConfigError
        A folder given is not an existing folder (named in the message).
    """
    entries = [e for e in environ.get(APP_ROOTS_ENV, "").split(os.pathsep) if e.strip()]
    for folder in allow:
        path = Path(folder).expanduser()
        if not path.is_dir():
            raise ConfigError(f"--allow {folder}: not an existing folder")
        resolved = str(path.resolve())
        if resolved not in entries:
            entries.append(resolved)
    return os.pathsep.join(entries)


def streamlit_args(args: argparse.Namespace) -> list[str]:
    """The arguments of ``streamlit`` that serve the packaged app with ``args``' address and port."""
    from ..app import HOME

    if not 0 < args.port < 65536:
        raise ConfigError(f"--port {args.port}: a port is between 1 and 65535")
    if not args.address.strip():
        raise ConfigError("--address: give an address to listen on (127.0.0.1 for this machine only)")
    flags = {**APP_FLAGS, "server.address": args.address, "server.port": str(args.port)}
    return ["run", str(HOME), *(part for key, value in flags.items() for part in (f"--{key}", value))]


def _is_loopback(address: str) -> bool:
    try:
        return ipaddress.ip_address(address).is_loopback
    except ValueError:
        return address == "localhost"


def run(args: argparse.Namespace) -> int:
    """Serve the app until interrupted; returns the exit status."""
    if importlib.util.find_spec("streamlit") is None:
        raise MissingDependencyError(
            "the app needs streamlit, which is not installed; install it with pip install 'gesturekit[app]'"
        )
    argv = streamlit_args(args)
    os.environ[APP_ROOTS_ENV] = app_roots(args.allow, os.environ)
    if args.search_device:
        from ..synthesis.synthesizer import SEARCH_DEVICE_ENV, open_search_device

        device = open_search_device(args.search_device)  # an absent one is said now, not at the first synthesis
        os.environ[SEARCH_DEVICE_ENV] = device or ""
        print(f"gesturekit: the search scans on {device or 'the CPU'}", flush=True)
    if not _is_loopback(args.address):
        print(
            f"gesturekit: serving to other machines on {args.address}: whoever reaches it can read and write "
            "the allowed folders; the Study page asks for the study's password",
            flush=True,
        )
    from ..app.launch import serve

    return serve(argv)
