"""``gesturekit app`` and ``gesturekit --version``: the packaged app served with the app's safe settings."""

from __future__ import annotations

import os
import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest
import tomllib

from gesturekit._version import __version__
from gesturekit.app import HOME
from gesturekit.cli import build_parser, main
from gesturekit.cli._app import APP_FLAGS, app_roots, streamlit_args
from gesturekit.errors import ConfigError
from gesturekit.paths import APP_ROOTS_ENV
from tests import app_browser
from tests.waits import patience, wait_until

ROOT = Path(__file__).resolve().parents[2]


def _flags(argv: list[str]) -> dict[str, str]:
    """``--key value`` pairs of a streamlit command line, after ``run SCRIPT``."""
    assert argv[:2] == ["run", str(HOME)]
    rest = argv[2:]
    assert len(rest) % 2 == 0 and all(k.startswith("--") for k in rest[::2])
    return {k[2:]: v for k, v in zip(rest[::2], rest[1::2])}


def test_version_prints_the_package_version(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out == f"gesturekit {__version__}\n"


def test_the_defaults_are_the_clones_config_and_this_machine_only():
    """What ``.streamlit/config.toml`` sets for ``streamlit run app/Home.py`` in a clone, the command's
    flags set from any folder: every key, the same value."""
    flags = _flags(streamlit_args(build_parser().parse_args(["app"])))
    config = tomllib.loads((ROOT / ".streamlit" / "config.toml").read_text(encoding="utf-8"))
    from_config = {f"{section}.{key}": value for section, values in config.items() for key, value in values.items()}
    assert from_config, "the clone's config sets nothing"
    for key, value in from_config.items():
        assert flags[key] == str(value).lower() if isinstance(value, bool) else flags[key] == str(value), key
    assert flags["server.address"] == "127.0.0.1" and flags["server.port"] == "8501"
    assert flags["browser.gatherUsageStats"] == "false" and flags["server.headless"] == "true"
    assert set(APP_FLAGS) < set(flags)


def test_address_and_port_are_passed_and_checked():
    args = build_parser().parse_args(["app", "--address", "0.0.0.0", "--port", "9000"])
    flags = _flags(streamlit_args(args))
    assert (flags["server.address"], flags["server.port"]) == ("0.0.0.0", "9000")
    assert _flags(streamlit_args(build_parser().parse_args(["app", "--host", "::1"])))["server.address"] == "::1"
    for bad in (["--port", "0"], ["--port", "70000"], ["--address", " "]):
        with pytest.raises(ConfigError, match=bad[0]):
            streamlit_args(build_parser().parse_args(["app", *bad]))


def test_allow_adds_existing_folders_to_the_roots_the_environment_gives(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "takes").mkdir()
    (tmp_path / "studies").mkdir()
    env = {APP_ROOTS_ENV: f"/srv/shared{os.pathsep}{os.pathsep}"}
    roots = app_roots(["takes", str(tmp_path / "studies"), "takes"], env).split(os.pathsep)
    assert roots == ["/srv/shared", str(tmp_path / "takes"), str(tmp_path / "studies")]  # absolute, once each
    assert app_roots([], {}) == ""
    (tmp_path / "file.txt").write_text("x")
    for bad in ("missing", "file.txt"):
        with pytest.raises(ConfigError, match=f"--allow {bad}: not an existing folder"):
            app_roots([bad], env)


def test_the_command_hands_streamlit_its_flags_and_the_app_its_folders(tmp_path, monkeypatch):
    """What ``gesturekit app`` starts: Streamlit's command line on the packaged entrypoint, with the
    allowed folders in the environment the app reads them from."""
    import gesturekit.app.launch

    seen = {}

    def serve(argv):
        seen["argv"], seen["roots"] = list(argv), os.environ.get(APP_ROOTS_ENV)
        return 0

    monkeypatch.setattr(gesturekit.app.launch, "serve", serve)
    monkeypatch.setenv(APP_ROOTS_ENV, "/srv/shared")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "takes").mkdir()
    assert main(["app", "--port", "8600", "--allow", "takes"]) == 0
    assert _flags(seen["argv"])["server.port"] == "8600"
    assert seen["roots"] == f"/srv/shared{os.pathsep}{tmp_path / 'takes'}"


def test_a_missing_folder_is_one_line_and_status_2(tmp_path, capsys):
    assert main(["app", "--allow", str(tmp_path / "nowhere")]) == 2
    assert capsys.readouterr().err == f"gesturekit: error: --allow {tmp_path / 'nowhere'}: not an existing folder\n"


@pytest.mark.slow
def test_the_command_serves_the_packaged_app_on_127_0_0_1_from_any_folder(demo_home, tmp_path):
    """Started from a folder without ``.streamlit/config.toml``, the server still listens on the loopback
    only, and serves the app's page."""
    from tests.app.test_app_security import _listening

    if not Path("/proc/net/tcp").is_file():
        pytest.skip("needs Linux's /proc/net/tcp to see which addresses the server listens on")
    (tmp_path / "takes").mkdir()
    port = app_browser._free_port()
    env = {**os.environ, "GESTUREKIT_HOME": str(demo_home), "PYTHONPATH": str(ROOT)}
    env.pop(APP_ROOTS_ENV, None)
    log = tmp_path / "app.log"
    cmd = [sys.executable, "-m", "gesturekit", "app", "--port", str(port), "--allow", "takes"]
    with log.open("wb") as out:
        proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=out, stderr=subprocess.STDOUT)
    try:

        def health() -> str | None:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/_stcore/health", timeout=patience(10)) as r:
                    return r.read().decode()
            except OSError:
                return None

        def exited() -> str | None:
            return None if proc.poll() is None else log.read_text(errors="replace")

        answer = wait_until(health, what="gesturekit app answers", timeout_s=300, give_up=exited)
        assert answer == "ok"
        assert _listening(port) == {"127.0.0.1"}
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=patience(30)) as r:
            assert r.status == 200 and b"<noscript>" in r.read()  # Streamlit's page, for the browser to draw
    finally:
        app_browser.stop(proc)
    assert proc.returncode in (0, -15), log.read_text(errors="replace")


def test_search_device_reaches_the_app_and_an_absent_one_is_said_before_serving(monkeypatch, capsys):
    pytest.importorskip("torch")
    import gesturekit.app.launch
    from gesturekit.synthesis import SEARCH_DEVICE_ENV, search_device_default

    seen = {}

    def serve(argv):
        seen["device"] = search_device_default()
        return 0

    monkeypatch.setattr(gesturekit.app.launch, "serve", serve)
    monkeypatch.delenv(SEARCH_DEVICE_ENV, raising=False)
    assert main(["app", "--search-device", "cpu:0"]) == 0
    assert seen["device"] == "cpu:0" and "scans on cpu:0" in capsys.readouterr().out
    seen.clear()
    assert main(["app", "--search-device", "nowhere:7"]) == 2
    assert not seen and "search device 'nowhere:7' is not a torch device" in capsys.readouterr().err
