"""The analysis at its edges, where it must say that it cannot say much.

- a pair of systems nobody rated together is listed as "not compared", and the Holm family size is stated;
- pairwise answers that do not connect every system: the comparison graph is called disconnected and each
  connected part is scored on its own (mean 0 within it), never with zero-width intervals;
- a system with fewer participants than the minimum gets no interval (NaN, "-" in the report) and a warning;
  an interval of zero width is never printed as an interval;
- the Wilcoxon p-value's method is explicit: exact (checked against a brute-force enumeration of the
  sign flips, an independent implementation) without ties at small n (zero differences dropped), else the normal
  approximation with the tie correction (checked against its textbook formula);
- the significance matrix's colour follows the test (the rank-biserial sign), not the mean difference.
"""

from __future__ import annotations

import math
from itertools import product

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import norm, rankdata

from gesturekit.errors import ConfigError
from gesturekit.study import analyse as A
from gesturekit.study.report import analyse, significance_figure, write_report

pytest.importorskip("choix")


def _ratings(rows):
    """A ratings table from (participant, system, value) with one speech and one prompt."""
    return pd.DataFrame([(p, 1, "s1", s, "natural", float(v)) for p, s, v in rows], columns=A.RATING_COLUMNS)


def _people(tokens):
    return pd.DataFrame([(t, 1, 0, False, False) for t in tokens], columns=A.EXCLUSION_COLUMNS)


def _empty_pairwise():
    return pd.DataFrame(columns=A.PAIRWISE_COLUMNS)


@pytest.mark.slow  # writes the report's figures
def test_a_pair_nobody_rated_together_is_listed_as_not_compared_and_the_family_size_is_stated(tmp_path):
    rows = []
    for i in range(8):  # A and B by everyone; C only by those who did not see... nobody rates A with C
        rows += [(f"p{i}", "A", 5 + i % 2), (f"p{i}", "B", 3)]
    for i in range(8, 16):
        rows += [(f"p{i}", "B", 4), (f"p{i}", "C", 2 + i % 3)]
    ratings = _ratings(rows)
    tests = A.pairwise_tests(ratings)
    every = tests[tests["prompt"] == "all"].set_index(["system_a", "system_b"])
    assert every.loc[("A", "C"), "n"] == 0 and every.loc[("A", "C"), "result"] == "not compared"
    assert math.isnan(every.loc[("A", "C"), "p"]) and not every.loc[("A", "C"), "significant"]
    assert set(every["family"]) == {2}  # A-B and B-C: Holm over 2 tests, not 3
    report = analyse(ratings, _empty_pairwise(), _people(sorted({r[0] for r in rows})), rounds=50)
    md = report.markdown()
    assert "Not compared (nobody rated both): A vs C" in md
    assert "Holm family per prompt: 2 tests" in md
    write_report(report, tmp_path / "out")
    written = pd.read_csv(tmp_path / "out" / "tests.csv")
    assert "not compared" in set(written["result"])


def _pairs(rows):
    return pd.DataFrame([(p, 1, "s1", a, b, float(v)) for p, a, b, v in rows], columns=A.PAIRWISE_COLUMNS)


def test_a_disconnected_comparison_graph_is_said_and_each_part_scored_on_its_own():
    rows = []
    for i in range(10):
        rows += [(f"p{i}", "A", "B", -2 if i < 7 else 2), (f"p{i}", "C", "D", 2 if i < 6 else -1)]
    pairwise = _pairs(rows)
    assert A.comparison_groups(pairwise) == [["A", "B"], ["C", "D"]]
    bt = A.bradley_terry(pairwise, rounds=200).set_index("system")
    assert bt.loc[["A", "B"], "group"].nunique() == 1 and bt.loc["A", "group"] != bt.loc["C", "group"]
    for part in (["A", "B"], ["C", "D"]):
        assert abs(bt.loc[part, "elo"].sum()) < 1e-6  # anchored within its own part
        assert (bt.loc[part, "elo_hi"] > bt.loc[part, "elo_lo"]).all()
    assert bt.loc["A", "elo"] > bt.loc["B", "elo"] and bt.loc["D", "elo"] > bt.loc["C", "elo"]
    # each part's scores are those of its own data alone
    alone = A.bradley_terry(pairwise[pairwise["system_left"] == "A"], rounds=200).set_index("system")
    np.testing.assert_allclose(bt.loc[["A", "B"], "elo"], alone.loc[["A", "B"], "elo"], atol=1e-6)
    report = analyse(pd.DataFrame(columns=A.RATING_COLUMNS), pairwise, _people([f"p{i}" for i in range(10)]), rounds=50)
    assert any("disconnected" in w and "A, B | C, D" in w for w in report.warnings)
    assert "disconnected" in report.markdown()


def test_too_few_participants_get_no_interval_and_a_warning():
    rows = [("p0", "A", 7), ("p0", "B", 3)]  # A by one participant
    rows += [(f"p{i}", "B", 3 + i % 3) for i in range(1, 3)] + [(f"p{i}", "C", 4) for i in range(1, 3)]
    rows += [(f"q{i}", s, 5) for i in range(6) for s in ("D", "E")]  # D, E: enough people, all alike
    rows += [(f"q{i}", "E", 2 + i) for i in range(6, 12)] + [(f"q{i}", "D", 6) for i in range(6, 12)]
    ratings = _ratings(rows)
    summary = A.system_summary(ratings, rounds=200)
    every = summary[summary["prompt"] == "all"].set_index("system")
    assert every.loc["A", "n"] == 1 and np.isnan(every.loc["A", ["mean_lo", "mean_hi"]].astype(float)).all()
    assert every.loc["C", "n"] == 2 and np.isnan(every.loc["C", ["median_lo", "median_hi"]].astype(float)).all()
    assert (every.loc[["D", "E"], "mean_hi"] > every.loc[["D", "E"], "mean_lo"]).all()
    # whatever the n, no interval of zero width is given
    lo, hi = summary["mean_lo"].to_numpy(float), summary["mean_hi"].to_numpy(float)
    assert not np.any(np.isfinite(lo) & (lo == hi))
    report = analyse(ratings, _empty_pairwise(), _people(sorted({r[0] for r in rows})), rounds=200)
    text = report.markdown()
    assert any(f"fewer than {A.MIN_INTERVAL_N} participants" in w and "A (1)" in w for w in report.warnings)
    assert "[7.0, 7.0]" not in text and "| 7.000 | 7.000 |" not in text
    assert "| A | 1 | 7.000 | - | - |" in text


def test_identical_values_give_no_zero_width_interval():
    ratings = _ratings([(f"p{i}", s, 4 if s == "A" else 3 + i % 2) for i in range(8) for s in ("A", "B")])
    every = A.system_summary(ratings, rounds=200).query("prompt == 'all'").set_index("system")
    assert every.loc["A", "mean"] == 4.0 and np.isnan(float(every.loc["A", "mean_lo"]))


def _exact_two_sided(d):
    """The exact two-sided Wilcoxon p by enumerating every sign pattern (no ties, no zeros)."""
    ranks = rankdata(np.abs(d))
    observed = ranks[d > 0].sum()
    total = ranks.sum()
    stats = [sum(r for r, s in zip(ranks, signs) if s) for signs in product((0, 1), repeat=len(d))]
    stats = np.array(stats)
    t = min(observed, total - observed)
    return min(1.0, 2 * np.mean(stats <= t + 1e-9))


def _normal_tied(d):
    """The normal approximation with the tie correction (no continuity correction), zeros dropped."""
    d = d[d != 0]
    n = d.size
    ranks = rankdata(np.abs(d))
    r_plus = ranks[d > 0].sum()
    _, counts = np.unique(np.abs(d), return_counts=True)
    var = n * (n + 1) * (2 * n + 1) / 24 - (counts**3 - counts).sum() / 48
    z = (r_plus - n * (n + 1) / 4) / math.sqrt(var)
    return 2 * norm.sf(abs(z))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(-30, 30), min_size=2, max_size=12))
def test_the_wilcoxon_p_value_method_is_explicit_and_matches_independent_computations(diffs):
    d = np.asarray(diffs, dtype=float)
    if not np.any(d != 0):
        return
    p, method = A.wilcoxon_p(d)
    nonzero = d[d != 0]
    if np.unique(np.abs(nonzero)).size == nonzero.size and nonzero.size <= A.EXACT_MAX_N:
        assert method == "exact"  # zero differences dropped, as Wilcoxon does
        assert p == pytest.approx(_exact_two_sided(nonzero), abs=1e-12)
    else:
        assert method == "normal, tie-corrected"
        assert p == pytest.approx(_normal_tied(d), rel=1e-9)


def test_the_tests_table_says_its_method():
    ratings = _ratings([(f"p{i}", s, v) for i in range(7) for s, v in (("A", 1 + i), ("B", 3))])
    tests = A.pairwise_tests(ratings)
    assert set(tests["method"]) == {"normal, tie-corrected"}  # the tie at |d| = 1 and the zero at p2
    ratings = _ratings([(f"p{i}", s, v) for i in range(7) for s, v in (("A", 10 + i * i), ("B", 3.5))])
    assert set(A.pairwise_tests(ratings)["method"]) == {"exact"}


def test_the_significance_colour_follows_the_test_not_the_mean_difference():
    # 19 participants rate A one below B, one rates A 100 above: the mean difference is positive, yet the
    # signed-rank test finds A lower (r < 0), significantly
    rows = [(f"p{i}", s, v) for i in range(19) for s, v in (("A", 3), ("B", 4))]
    rows += [("p19", "A", 104), ("p19", "B", 4)]
    ratings = _ratings(rows)
    tests = A.pairwise_tests(ratings).query("prompt == 'all'").iloc[0]
    assert tests["mean_diff"] > 0 and tests["r"] < 0 and tests["significant"]
    report = analyse(ratings, _empty_pairwise(), _people([f"p{i}" for i in range(20)]), rounds=50)
    fig = significance_figure(report)
    heat = [t for t in fig.data if t.type == "heatmap"][-1]  # the "all" prompt
    order = list(heat.y)
    z = np.asarray(heat.z, dtype=float)
    assert z[order.index("A"), order.index("B")] == -1.0 and z[order.index("B"), order.index("A")] == 1.0


def test_the_bootstrap_rounds_are_bounded():
    ratings = _ratings([(f"p{i}", s, 1 + (i * 3 + len(s)) % 7) for i in range(6) for s in ("A", "B")])
    with pytest.raises(ConfigError, match="at most"):
        analyse(ratings, _empty_pairwise(), _people([f"p{i}" for i in range(6)]), rounds=1_000_000_000)


def test_the_analyse_help_prints_a_plain_percent(capsys):
    from gesturekit.cli import main

    with pytest.raises(SystemExit):
        main(["study", "analyse", "--help"])
    out = capsys.readouterr().out
    assert "95 % intervals" in out and "%%" not in out
