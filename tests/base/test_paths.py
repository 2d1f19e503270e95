"""gesturekit.paths: gesturekit's home, and the folders a served app may read and write."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gesturekit.errors import ConfigError, GestureKitError
from gesturekit.paths import APP_ROOTS_ENV, allowed_roots, assets, check_allowed, home, is_allowed


@pytest.fixture
def roots(tmp_path, monkeypatch) -> dict[str, Path]:
    """A home, a working directory and an extra root, side by side with a folder outside them all."""
    base = tmp_path.resolve()
    named = {name: base / name for name in ("home", "work", "extra", "outside")}
    for folder in named.values():
        folder.mkdir()
    monkeypatch.setenv("GESTUREKIT_HOME", str(named["home"]))
    monkeypatch.setenv(APP_ROOTS_ENV, str(named["extra"]))
    monkeypatch.chdir(named["work"])
    return named


def test_the_roots_are_home_the_working_directorys_db_the_listed_ones_and_the_assets_for_reading(roots):
    assert allowed_roots() == (roots["home"], roots["work"] / "db", roots["extra"], assets())
    assert allowed_roots(write=True) == (roots["home"], roots["work"] / "db", roots["extra"])
    assert (assets() / "demo-refiner" / "config.json").is_file()  # the shipped refiner can be read


def test_the_variable_lists_several_roots_skipping_empty_entries_and_repeats(roots, monkeypatch):
    monkeypatch.setenv(APP_ROOTS_ENV, os.pathsep.join(["", str(roots["extra"]), " ", "rel", str(roots["home"])]))
    assert allowed_roots(write=True) == (roots["home"], roots["work"] / "db", roots["extra"], roots["work"] / "rel")
    monkeypatch.delenv(APP_ROOTS_ENV)
    assert allowed_roots(write=True) == (roots["home"], roots["work"] / "db")


def test_home_defaults_to_the_users_cache(monkeypatch):
    monkeypatch.delenv("GESTUREKIT_HOME", raising=False)
    assert home() == Path.home() / ".cache" / "gesturekit"


@pytest.mark.parametrize("typed", ["home", "home/db/demo", "work/db", "work/db/new/deeper", "extra/x/../y"])
def test_paths_inside_a_root_are_allowed_and_returned_resolved(roots, typed):
    path = roots["home"].parent / typed
    assert check_allowed(path, what="database folder") == Path(os.path.normpath(path))
    assert is_allowed(path) and is_allowed(path, write=True)


@pytest.mark.parametrize("typed", ["outside", "outside/db", "work", "work/dbx", "home/../outside", "/etc", "/"])
def test_paths_outside_every_root_are_refused_naming_the_path_and_how_to_add_a_folder(roots, typed):
    path = typed if typed.startswith("/") else str(roots["home"].parent / typed)
    with pytest.raises(ConfigError) as refused:
        check_allowed(path, what="database folder")
    assert isinstance(refused.value, GestureKitError)
    message = str(refused.value)
    assert message == (
        f"{path}: the database folder is outside the allowed folders; whoever runs the server can allow "
        f"a folder by adding it to the {APP_ROOTS_ENV} environment variable"
    )
    # the server's own folders (its home, the package's install path) are not told to a visitor
    for root in allowed_roots():
        assert str(root) not in message[len(path) :]
    assert not is_allowed(path)


def test_the_message_is_the_same_whether_the_path_exists_or_not(roots):
    messages = []
    for name in ("outside", "nowhere"):  # the first exists, the second does not
        with pytest.raises(ConfigError) as refused:
            check_allowed(roots["home"].parent / name, what="folder of takes")
        messages.append(str(refused.value).split(": ", 1)[1])
    assert messages[0] == messages[1]


def test_a_symlink_out_of_a_root_is_refused_and_one_into_a_root_is_allowed(roots):
    (roots["home"] / "escape").symlink_to(roots["outside"], target_is_directory=True)
    (roots["outside"] / "way-in").symlink_to(roots["extra"], target_is_directory=True)
    with pytest.raises(ConfigError):
        check_allowed(roots["home"] / "escape" / "db", what="database folder")
    assert check_allowed(roots["outside"] / "way-in", what="database folder") == roots["extra"]


def test_the_packages_assets_are_read_only(roots):
    assert check_allowed(assets() / "demo-refiner", what="refiner folder") == assets() / "demo-refiner"
    with pytest.raises(ConfigError, match="outside the allowed folders for writing"):
        check_allowed(assets() / "new-db", what="database folder to write", write=True)


@pytest.mark.parametrize("typed", ["", "   "])
def test_an_empty_path_asks_for_one(roots, typed):
    with pytest.raises(ConfigError, match="^type the study folder to write$"):
        check_allowed(typed, what="study folder to write", write=True)


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(parts=st.lists(st.sampled_from(["a", "b", "..", "."]), max_size=6))
def test_dot_dot_cannot_leave_a_root(roots, parts):
    """Without links, a path is allowed exactly when its normalised form stays inside the root."""
    root = roots["extra"]
    typed = os.path.join(str(root), *parts)
    inside = Path(os.path.normpath(typed)).is_relative_to(root)
    assert is_allowed(typed) == inside
    if inside:
        assert check_allowed(typed, what="folder") == Path(os.path.normpath(typed))
    else:
        with pytest.raises(ConfigError):
            check_allowed(typed, what="folder")
