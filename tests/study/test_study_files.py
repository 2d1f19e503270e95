"""A study's own files as untrusted input: design.json that is a FIFO or nests without end, a responses CSV
whose answers cell nests without end. Each is a clear error naming the file, never a hang or a traceback."""

from __future__ import annotations

import os

import pytest

from gesturekit.errors import ConfigError
from gesturekit.study.analyse import read_responses_csv
from gesturekit.study.design import load_design


def test_a_fifo_design_is_refused_not_read(tmp_path):
    os.mkfifo(tmp_path / "design.json")
    with pytest.raises(ConfigError, match="FIFO") as err:
        load_design(tmp_path)
    assert "design.json" in str(err.value)


def test_a_deeply_nested_design_is_a_clear_error(tmp_path):
    (tmp_path / "design.json").write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(ConfigError, match="nests"):
        load_design(tmp_path)


def test_a_deeply_nested_answers_cell_is_a_clear_error(tmp_path):
    deep = "[" * 50_000 + "]" * 50_000
    (tmp_path / "r.csv").write_text(f"token,row,page_id,page_index,kind,answers\nt,1,p,0,rating,{deep}\n")
    with pytest.raises(ConfigError, match="nests") as err:
        read_responses_csv(tmp_path / "r.csv")
    assert "r.csv" in str(err.value)
