"""The app as served: local by default, only the allowed folders, no traceback or server path in
the browser. The server is started as a clone starts it (``streamlit run app/Home.py``); pages run
headless with AppTest."""

from __future__ import annotations

import ipaddress
import os
import re
import shutil
import socket
import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest
import soundfile as sf
import tomllib
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from streamlit.testing.v1 import AppTest

from gesturekit.app import HOME
from gesturekit.datasets.synthetic import generate_demo_take
from gesturekit.errors import ConfigError, InputFileError
from gesturekit.paths import APP_ROOTS_ENV, allowed_roots, check_allowed
from tests import app_browser
from tests.conftest import shown
from tests.waits import APP_RUN_S, patience, wait_until

ROOT = Path(__file__).resolve().parents[2]
STUDY_PAGE = "views/4_Study_stimuli.py"
SYNTH_PAGE = "views/1_Synthesize.py"
TIMEOUT = APP_RUN_S  # a script run's deadline, which ends a hang (tests/waits.py)
GENERIC = re.compile(r"^Something went wrong; the details are in the server log \(reference ([0-9a-f]{8})\)\.$")


# ---- the project's Streamlit config ------------------------------------------------------------


def test_the_config_binds_locally_hides_developer_options_and_error_details():
    config = tomllib.loads((ROOT / ".streamlit" / "config.toml").read_text(encoding="utf-8"))
    assert config["server"]["address"] == "127.0.0.1"
    assert config["client"]["toolbarMode"] == "viewer"
    assert config["client"]["showErrorDetails"] == "none"  # generic message; details to the console
    assert 0 < config["server"]["maxUploadSize"] <= 200  # MB: an hour of compressed speech


def test_the_installed_streamlit_accepts_the_config_values():
    """Streamlit falls back to its default for a value it does not know: read them through it."""
    script = f"""
import sys
from streamlit import config
config._main_script_path = {str(HOME)!r}
config.get_config_options(force_reparse=True)
for key in ("server.address", "client.toolbarMode", "client.showErrorDetails", "server.maxUploadSize"):
    print(key, config.get_option(key), config.get_where_defined(key))
"""
    out = subprocess.run(
        [sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=patience(300)
    )
    assert out.returncode == 0, out.stderr
    values = dict(line.split(" ", 1) for line in out.stdout.splitlines())
    where = str(ROOT / ".streamlit" / "config.toml")
    assert values["server.address"] == f"127.0.0.1 {where}"
    assert values["client.toolbarMode"] == f"viewer {where}"
    assert values["client.showErrorDetails"] == f"none {where}"


# ---- the server, started from a clone -----------------------------------------------------------


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _listening(port: int) -> set[str]:
    """Addresses with a listening TCP socket on ``port``, from /proc/net/tcp and tcp6."""
    found = set()
    for table, width in (("/proc/net/tcp", 4), ("/proc/net/tcp6", 16)):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            address, hex_port = fields[1].split(":")
            if fields[3] != "0A" or int(hex_port, 16) != port:  # 0A: LISTEN
                continue
            raw = bytes.fromhex(address)
            # the kernel prints the address as 32-bit words in host (little-endian) order
            words = b"".join(raw[i : i + 4][::-1] for i in range(0, len(raw), 4))
            found.add(str(ipaddress.ip_address(words[:width])))
    return found


@pytest.mark.slow
def test_the_clone_command_serves_on_127_0_0_1_only(demo_home, tmp_path):
    """``streamlit run app/Home.py`` from a clone's root (the app guide's second command; the README's,
    ``gesturekit app``, is tests/cli/test_cli_app.py's) reads .streamlit/config.toml's address."""
    if not Path("/proc/net/tcp").is_file():
        pytest.skip("needs Linux's /proc/net/tcp to see which addresses the server listens on")
    guide = (ROOT / "docs" / "guides" / "app.md").read_text(encoding="utf-8")
    assert "\nstreamlit run app/Home.py " in guide  # the launch command, from the repository root
    port = _free_port()
    env = {**os.environ, "GESTUREKIT_HOME": str(demo_home), "PYTHONPATH": str(ROOT)}
    env.pop(APP_ROOTS_ENV, None)
    log = tmp_path / "streamlit.log"
    cmd = [
        sys.executable,
        "-m",
        "streamlit",
        "run",
        "app/Home.py",
        "--server.port",
        str(port),
        "--server.headless",
        "true",
    ]
    with log.open("wb") as out:
        proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=out, stderr=subprocess.STDOUT)
    try:

        def health() -> str | None:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/_stcore/health", timeout=patience(10)) as r:
                    return r.read().decode()
            except OSError:
                return None

        def exited() -> str | None:
            return None if proc.poll() is None else log.read_text(errors="replace")

        answer = wait_until(health, what="streamlit answers", timeout_s=180, interval_s=0.2, give_up=exited)
        assert answer == "ok"
        assert _listening(port) == {"127.0.0.1"}  # not 0.0.0.0, not ::
    finally:
        app_browser.stop(proc)


# ---- allowed folders ----------------------------------------------------------------------------


@pytest.fixture
def outside(tmp_path_factory) -> Path:
    """A folder of the server outside the allowed roots (a sibling of the test's own folder)."""
    return tmp_path_factory.mktemp("outside")


def _texts(at: AppTest) -> str:
    """Everything the page shows as text, for checks that something is absent."""
    parts = []
    for kind in ("markdown", "caption", "error", "warning", "info", "success", "text", "code", "exception"):
        for el in at.get(kind):
            value = str(getattr(el, "value", ""))
            # as a reader sees it: the source of Markdown elements holds escapes (\/srv\/private)
            parts.append((shown(value) if kind not in ("text", "code", "exception") else value) + value)
            parts.append(str(getattr(el.proto, "message", "")))
    for frame in at.get("dataframe"):
        parts.append(frame.value.to_string())
    return "\n".join(parts)


def _refusal(message: str, typed: str, what: str) -> str:
    """The message with the typed path taken out: what a refusal of that kind says."""
    assert message.startswith(f"{typed}: the {what} is outside the allowed folders"), message
    assert APP_ROOTS_ENV in message
    return message[len(typed) :]


def _type_database(at: AppTest, path: str) -> AppTest:
    at.sidebar.selectbox[0].select_index(-1).run()  # "another folder…"
    return at.sidebar.text_input(key="_gk.database_typed").input(path).run()


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["a database", "missing", "dot-dot", "symlink"])
def test_a_database_outside_the_allowed_folders_is_refused_alike(app_env, tmp_path, outside, kind):
    db = outside / "db"
    shutil.copytree(app_env / "db" / "demo", db)  # a readable database: only the rule stops it
    if kind == "symlink":  # a link inside an allowed folder to a folder outside
        (tmp_path / "link").symlink_to(db, target_is_directory=True)
    typed = {
        "a database": str(db),
        "missing": str(outside / "nowhere"),
        "dot-dot": str(tmp_path / ".." / outside.name / "db"),
        "symlink": str(tmp_path / "link"),
    }[kind]
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    _type_database(at, typed)
    assert not at.exception
    (message,) = [shown(e.value) for e in at.error]
    said = _refusal(message, typed, "database folder")
    for root in allowed_roots():  # no server path: not the home, not the package's install path
        assert str(root) not in said
    # the same words whether the folder holds a database or nothing at all: no probing
    with pytest.raises(ConfigError) as missing:
        check_allowed(outside / "nowhere", what="database folder")
    assert said == str(missing.value)[len(str(outside / "nowhere")) :]
    # nothing of the database is shown
    assert not at.get("dataframe") and not at.get("component_instance") and not at.get("plotly_chart")
    assert "clip" not in " ".join(c.value for c in at.sidebar.caption)


@pytest.mark.slow
def test_a_database_inside_an_allowed_root_from_the_environment_opens(app_env, outside, monkeypatch):
    shutil.copytree(app_env / "db" / "demo", outside / "db")
    monkeypatch.setenv(APP_ROOTS_ENV, os.pathsep.join(["", str(outside)]))
    at = _type_database(AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run(), str(outside / "db"))
    assert not at.exception and not at.error
    # the folder typed is the one opened (the page names it, not its server path) and its clips are counted
    assert Path(at.session_state["gk.database"]).resolve() == (outside / "db").resolve()
    captions = " ".join(shown(c.value) for c in at.sidebar.caption)
    assert " clips" in captions and str(outside) not in captions


def _study_page() -> AppTest:
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    at.switch_page(STUDY_PAGE).run()
    assert not at.exception, at.exception
    return at


def _speech_folder(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    take, _ = generate_demo_take(seconds=2.0, seed=3, name="s")
    sf.write(folder / "private-interview.wav", take.audio[:19200], 16000)
    return folder


@pytest.mark.slow
@pytest.mark.parametrize("exists", [True, False])
def test_the_study_page_does_not_list_a_folder_outside(app_env, outside, exists):
    folder = _speech_folder(outside / "speech") if exists else outside / "speech"
    at = _study_page()
    at.text_input(key="_w.study.folder").set_value(str(folder)).run()
    assert not at.exception
    (message,) = [shown(e.value) for e in at.error]
    said = _refusal(message, str(folder), "folder of speech files")
    assert "no such folder" not in said
    assert "private-interview" not in _texts(at)  # the files are not listed
    assert not at.get("dataframe")


@pytest.mark.slow
def test_the_study_page_writes_no_study_outside(app_env, tmp_path, outside):
    speech = _speech_folder(tmp_path / "speech")
    target = outside / "study"
    at = _study_page()
    at.text_input(key="_w.study.folder").set_value(str(speech)).run()
    at.text_input(key="_w.study.out").set_value(str(target)).run()
    assert not at.exception and not at.error
    at.button(key="study.go").click().run()
    assert not at.exception
    (message,) = [shown(e.value) for e in at.error]
    _refusal(message, str(target), "study folder to write")
    assert list(outside.iterdir()) == []


def _build(at: AppTest, *, folder: str, out: str, joint_map: str | None = None) -> AppTest:
    at.sidebar.text_input(key="_gk.build_folder").input(folder)
    if joint_map is not None:
        at.sidebar.radio(key="_gk.build_naming").set_value("JSON joint map").run()
        at.sidebar.text_input(key="_gk.build_map").input(joint_map)
    at.sidebar.text_input(key="_gk.build_out").input(out)
    return at.sidebar.button(key="_gk.build_go").click().run()


@pytest.mark.slow
@pytest.mark.parametrize("case", ["output outside", "output in the package", "takes outside", "joint map outside"])
def test_building_a_database_reads_and_writes_only_allowed_folders(app_env, tmp_path, outside, case):
    import gesturekit

    takes = tmp_path / "takes"
    takes.mkdir()
    out = str(tmp_path / "built")
    folder, joint_map, typed, what = str(takes), None, None, None
    if case == "output outside":
        out = typed = str(outside / "built")
        what = "database folder to write"
    elif case == "output in the package":  # readable (the demo refiner), never written
        out = typed = str(Path(gesturekit.__file__).parent / "assets" / "built")
        what = "database folder to write"
    elif case == "takes outside":
        folder = typed = str(outside)
        what = "folder of takes"
    else:
        joint_map = typed = str(outside / "map.json")
        what = "joint map"
    at = _build(
        AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run(), folder=folder, out=out, joint_map=joint_map
    )
    assert not at.exception
    (message,) = [shown(e.value) for e in at.sidebar.error]
    _refusal(message, typed, what)
    assert list(outside.iterdir()) == [] and not (tmp_path / "built").exists()
    assert not (Path(gesturekit.__file__).parent / "assets" / "built").exists()


@pytest.mark.slow
def test_a_refiner_outside_is_refused_and_the_shipped_one_is_not(app_env, outside):
    (outside / "refiner").mkdir()
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    at.switch_page(SYNTH_PAGE).run()
    assert not at.exception and not at.error  # the demo database's default: the shipped refiner
    at.toggle(key="_w.synth.refine").set_value(True).run()
    assert not at.error
    at.text_input(key="_w.synth.refiner_path").input(str(outside / "refiner")).run()
    assert not at.exception
    (message,) = [shown(e.value) for e in at.error]
    _refusal(message, str(outside / "refiner"), "refiner folder")
    assert at.button(key="synth.go").disabled


# ---- nothing of the server in the browser --------------------------------------------------------


@pytest.mark.slow
def test_an_unexpected_error_shows_a_reference_not_a_traceback(app_env, monkeypatch, caplog):
    secret = "/srv/private/lab-notes"

    def broken(self):
        raise RuntimeError(f"bug while reading {secret}")

    monkeypatch.setattr("gesturekit.database.MatchingDatabase.describe", broken)
    with caplog.at_level("ERROR", logger="gesturekit.app"):
        at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    assert not at.exception
    (message,) = [shown(e.value) for e in at.error]
    reference = GENERIC.match(message).group(1)
    assert secret not in _texts(at) and "Traceback" not in _texts(at) and "RuntimeError" not in _texts(at)
    (record,) = [r for r in caplog.records if r.name == "gesturekit.app"]
    assert reference in record.getMessage() and secret in str(record.exc_info[1])
    # each error gets its own reference
    with caplog.at_level("ERROR", logger="gesturekit.app"):
        again = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    assert GENERIC.match(shown(again.error[0].value)).group(1) != reference


@pytest.mark.slow
@pytest.mark.parametrize("inside", [True, False], ids=["inside", "outside"])
@pytest.mark.parametrize("error", ["OSError", "GestureKitError"])
def test_a_file_error_names_a_server_path_only_inside_the_allowed_folders(
    app_env, tmp_path, monkeypatch, inside, error
):
    missing = (tmp_path if inside else Path("/srv/private")) / "stats.npz"

    def broken(self):
        if error == "OSError":
            raise FileNotFoundError(2, "No such file or directory", str(missing))
        raise InputFileError("No such file or directory", path=missing)

    monkeypatch.setattr("gesturekit.database.MatchingDatabase.describe", broken)
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    assert not at.exception
    (message,) = [shown(e.value) for e in at.error]
    assert message == f"{missing if inside else 'stats.npz'}: No such file or directory"
    assert inside or "/srv/private" not in _texts(at)


@pytest.mark.slow
@settings(
    max_examples=50, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(
    parts=st.lists(
        st.text(st.characters(blacklist_characters="/\0", blacklist_categories=["Cs"]), min_size=1, max_size=8).filter(
            lambda p: p not in (".", "..")
        ),
        min_size=1,
        max_size=4,
    ),
    kind=st.sampled_from(["OSError", "GestureKitError"]),
)
def test_an_error_text_keeps_folders_outside_private(app_env, outside, monkeypatch, parts, kind):
    """Whatever the file, only its last part is shown when it lies outside the allowed folders."""
    from gesturekit.app import display

    path = outside.joinpath(*parts)
    exc = (
        PermissionError(13, "Permission denied", str(path))
        if kind == "OSError"
        else InputFileError("cannot be read", path=path)
    )
    text = display.error_text(exc)
    assert text == f"{parts[-1]}: " + ("Permission denied" if kind == "OSError" else "cannot be read")
    assert str(outside) not in text
