"""The study's analysis (gesturekit.study.analyse, .report) on simulated participants with a known truth.

- The true order of the systems is recovered from ratings (means, Wilcoxon-Holm) and from pairwise
  answers (Bradley-Terry); with no true difference, the family-wise false-positive rate of the Holm
  corrected Wilcoxon tests over 400 simulated studies lies in the binomial 99 % interval around alpha.
- Holm equals statsmodels' ``multipletests(method="holm")`` and a plain step-down reference; the
  rank-biserial r agrees with scipy's Wilcoxon statistic; the vectorised Bradley-Terry fit equals choix;
  the vectorised bootstrap equals a loop, and its intervals cover the true mean about 95 % of the time.
- Excluded participants are left out; the report's files are written atomically, name every system,
  and are not replaced without force; an empty or too small study is a clear error.
- On a real study folder (design, store): a participant failing both attention checks is excluded,
  `gesturekit study analyse` writes the report with the right order, and the same responses read
  from a CSV (as import-hemvip writes them) give the same numbers.
"""

from __future__ import annotations

import shutil

import numpy as np
import pandas as pd
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy import stats

from gesturekit.errors import ConfigError, OutputError
from gesturekit.study import analyse as A
from gesturekit.study import bradley_terry as BT
from gesturekit.study.report import REPORT_FILES, analyse, write_report
from gesturekit.study.simulate import simulate_study
from tests.study_helpers import tiny_study  # noqa: F401 (a fixture)

choix = pytest.importorskip("choix")

p_values = st.lists(st.floats(min_value=0.0, max_value=1.0, allow_nan=False), min_size=0, max_size=12)


def _holm_reference(p: list[float]) -> np.ndarray:
    """Holm's adjusted p-values by the textbook loops: max over the smaller ones of (m - rank) p, capped at 1."""
    m = len(p)
    order = sorted(range(m), key=lambda i: (p[i], i))
    out = [0.0] * m
    for rank, i in enumerate(order):
        out[i] = min(1.0, max((m - r) * p[order[r]] for r in range(rank + 1)))
    return np.array(out)


def _step_down_rejects(p: list[float], alpha: float) -> np.ndarray:
    """Holm's procedure itself: reject the smallest p-values while p_(i) <= alpha / (m - i)."""
    m = len(p)
    reject = np.zeros(m, dtype=bool)
    for rank, i in enumerate(sorted(range(m), key=lambda i: (p[i], i))):
        if p[i] > alpha / (m - rank):
            break
        reject[i] = True
    return reject


@settings(max_examples=200, deadline=None)
@given(p_values, st.sampled_from([0.01, 0.05, 0.1]))
def test_holm_equals_the_plain_step_down_procedure(p, alpha):
    adjusted = A.holm(p)
    np.testing.assert_allclose(adjusted, _holm_reference(p), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(adjusted <= alpha, _step_down_rejects(p, alpha))
    assert np.all(adjusted >= np.asarray(p, dtype=float)) and np.all(adjusted <= 1)


# statsmodels' multipletests takes about 80 ms a call: fewer examples, and the edge cases named
@pytest.mark.slow
@settings(max_examples=40, deadline=None)
@given(p_values.filter(lambda p: len(p) > 0))
@example([0.01, 0.01, 0.04, 0.04, 0.5]).via("ties")
@example([0.0, 1.0, 0.3]).via("the ends")
@example([0.02]).via("one test")
def test_holm_equals_statsmodels(p):
    multipletests = pytest.importorskip("statsmodels.stats.multitest").multipletests
    np.testing.assert_allclose(A.holm(p), multipletests(p, method="holm")[1], rtol=1e-12, atol=1e-15)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(1, 7), st.integers(1, 7)), min_size=1, max_size=30))
def test_rank_biserial_agrees_with_the_wilcoxon_statistic(pairs):
    x, y = np.array(pairs, dtype=float).T
    r = A.rank_biserial(x, y)
    assert -1 <= r <= 1
    assert A.rank_biserial(y, x) == pytest.approx(-r)
    d = (x - y)[x != y]
    if d.size == 0:
        assert r == 0
        return
    # two-sided scipy: T = min(R+, R-); the ranks sum to n(n + 1) / 2, so |r| = 1 - 2 T / (n(n + 1) / 2)
    t = stats.wilcoxon(x, y, zero_method="wilcox", method="asymptotic").statistic
    assert abs(r) == pytest.approx(1 - 2 * t / (d.size * (d.size + 1) / 2), abs=1e-12)
    assert np.sign(r) == np.sign(np.sum(stats.rankdata(np.abs(d)) * np.sign(d)))


@pytest.mark.parametrize("k", [2, 3, 6])
def test_bradley_terry_fit_equals_choix(k):
    rng = np.random.default_rng(k)
    wins = rng.integers(0, 9, size=(5, k, k)).astype(float) * 2
    fast = A.bt_fit(wins, prior=1.0, tol=1e-13)
    for b in range(wins.shape[0]):
        np.testing.assert_allclose(fast[b], BT._bt_choix(choix, wins[b], 1.0), atol=1e-7)
        assert fast[b].mean() == pytest.approx(0, abs=1e-12)


def test_bootstrap_is_a_vectorised_loop_and_covers_the_true_mean():
    x = np.random.default_rng(1).normal(size=17)
    mean, lo, hi, median, dlo, dhi = A.bootstrap_mean_median(x, rounds=300, seed=5)
    idx = np.random.default_rng(5).integers(0, x.size, size=(300, x.size))
    loop_means = [float(np.mean(x[row])) for row in idx]
    loop_medians = [float(np.median(x[row])) for row in idx]
    assert (mean, median) == (pytest.approx(x.mean()), pytest.approx(np.median(x)))
    assert (lo, hi) == tuple(pytest.approx(v) for v in np.percentile(loop_means, [2.5, 97.5]))
    assert (dlo, dhi) == tuple(pytest.approx(v) for v in np.percentile(loop_medians, [2.5, 97.5]))
    # drawn in blocks of 4 M values (here 4000 rounds, then 1000): the same as one draw of them all
    big = np.random.default_rng(0).normal(size=1000)
    _, lo, hi, *_ = A.bootstrap_mean_median(big, rounds=5000, seed=3)
    one_draw = big[np.random.default_rng(3).integers(0, 1000, size=(5000, 1000))].mean(axis=1)
    assert (lo, hi) == tuple(pytest.approx(v, abs=1e-12) for v in np.percentile(one_draw, [2.5, 97.5]))
    # coverage of the true mean (0) by the 95 % interval over 300 samples of 30 participants
    rng = np.random.default_rng(2)
    covered = 0
    for i in range(300):
        _, lo, hi, *_ = A.bootstrap_mean_median(rng.normal(size=30), rounds=400, seed=i)
        covered += lo <= 0 <= hi
    assert 0.88 <= covered / 300 <= 0.99, covered


def test_the_true_order_is_recovered_from_ratings_and_from_pairwise_answers():
    truth = (5.2, 4.4, 3.6, 2.8)
    sim = simulate_study(truth, systems=["best", "good", "fair", "poor"], participants=30, careless=0.1, seed=3)
    report = analyse(sim.ratings, sim.pairwise, sim.exclusions, rounds=500, alpha=0.05)
    assert report.summary is not None and report.tests is not None and report.bradley_terry is not None
    for prompt in ("natural", "sync", "all"):
        assert list(report.summary.loc[report.summary["prompt"] == prompt, "system"]) == [
            "best",
            "good",
            "fair",
            "poor",
        ]
    every = report.tests[report.tests["prompt"] == "all"]
    assert every["significant"].all(), every
    # mean_diff and r say which system is better: the one listed first, by name order, is checked against truth
    for t in every.itertuples():
        better = sim.true_means[t.system_a] > sim.true_means[t.system_b]
        assert (t.mean_diff > 0) == better and (t.r > 0) == better
    assert list(report.bradley_terry["system"]) == ["best", "good", "fair", "poor"]
    assert report.bradley_terry["elo"].mean() == pytest.approx(0, abs=1e-9)
    bt = report.bradley_terry.set_index("system")
    assert bt.loc["best", "elo_lo"] > bt.loc["poor", "elo_hi"]
    assert (bt["elo_lo"] <= bt["elo"]).all() and (bt["elo"] <= bt["elo_hi"]).all()


@pytest.mark.slow
def test_with_no_difference_the_familywise_false_positive_rate_is_near_alpha():
    studies, alpha = 400, 0.05
    hits = 0
    for seed in range(studies):
        sim = simulate_study(
            (4.0, 4.0, 4.0), participants=20, speeches=3, prompts=("natural",), pairwise=False, careless=0, seed=seed
        )
        tests = A.pairwise_tests(sim.ratings, alpha=alpha)
        hits += bool(tests.loc[tests["prompt"] == "natural", "significant"].any())
    lo, hi = stats.binom.interval(0.99, studies, alpha)
    print(f"family-wise false positives: {hits} of {studies} (binomial 99 % interval {lo:.0f}..{hi:.0f})")
    assert lo <= hits <= hi


def test_excluded_participants_are_left_out():
    sim = simulate_study((5, 4, 3), participants=40, careless=0.3, seed=4)
    report = analyse(sim.ratings, sim.pairwise, sim.exclusions, rounds=200)
    excluded = set(sim.exclusions.loc[sim.exclusions["excluded"], "participant"])
    assert excluded and report.excluded == len(excluded) and report.included == 40 - len(excluded)
    assert not excluded & set(report.ratings["participant"]) and not excluded & set(report.pairwise["participant"])
    assert report.summary is not None and (report.summary["n"] == 40 - len(excluded)).all()
    # the checks find the careless (each excluded with probability 1 - 0.51 * 0.7 = 0.64), seldom the attentive
    attentive = 40 - len(sim.careless)
    assert len(excluded & sim.careless) / len(sim.careless) >= 0.4
    assert len(excluded - sim.careless) / attentive <= 0.1
    # exclusion follows the rule: more failures than allowed, or the audio check
    rule = (sim.exclusions["failed_checks"] > 1) | sim.exclusions["audio_failed"]
    assert (rule == sim.exclusions["excluded"]).all()


@pytest.mark.slow
def test_the_report_names_every_system_and_is_not_replaced_without_force(tmp_path):
    systems = ["gt", "knn", "knn+cgan"]
    sim = simulate_study((5, 4, 4.5), systems=systems, participants=12, seed=5)
    report = analyse(sim.ratings, sim.pairwise, sim.exclusions, rounds=100)
    out = tmp_path / "analysis"
    files = write_report(report, out)
    assert {f.name for f in files} >= set(REPORT_FILES)
    for name in ("report.md", "report.html", "summary.csv", "bradley_terry.csv"):
        text = (out / name).read_text()
        assert all(s in text for s in systems), name
    summary = pd.read_csv(out / "summary.csv")
    assert set(summary["system"]) == set(systems) and {"mean_lo", "median_hi"} <= set(summary.columns)
    assert "plotly" in (out / "significance.html").read_text()[:200000].lower()
    before = (out / "report.md").read_bytes()
    with pytest.raises(OutputError, match="--force"):
        write_report(analyse(sim.ratings, sim.pairwise, sim.exclusions, rounds=50), out)
    assert (out / "report.md").read_bytes() == before
    write_report(analyse(sim.ratings, sim.pairwise, sim.exclusions, rounds=50), out, force=True)
    assert "50 rounds" in (out / "report.md").read_text()


def test_simulated_answers_lie_on_the_scale():
    sim = simulate_study((80, 50, 20), scale="slider100", noise_sd=15, participant_sd=10, careless=0.2, seed=8)
    assert sim.ratings["value"].between(0, 100).all() and (sim.ratings["value"] % 1 == 0).all()
    assert sim.pairwise["value"].isin([-2, -1, 0, 1, 2]).all()
    assert len(sim.ratings) == 24 * 4 * 3 * 2 and len(sim.pairwise) == 24 * 4 * 3
    # every pair is shown both ways round, about equally often
    left_first = (sim.pairwise["system_left"] < sim.pairwise["system_right"]).mean()
    assert 0.35 < left_first < 0.65
    with pytest.raises(ConfigError, match="scale"):
        simulate_study(scale="likert5")


def test_the_analysis_is_deterministic():
    sim = simulate_study((5, 4, 3), participants=10, seed=6)
    one = analyse(sim.ratings, sim.pairwise, sim.exclusions, rounds=200, seed=1)
    two = analyse(sim.ratings, sim.pairwise, sim.exclusions, rounds=200, seed=1)
    pd.testing.assert_frame_equal(one.summary, two.summary)
    pd.testing.assert_frame_equal(one.bradley_terry, two.bradley_terry)


def test_an_empty_or_too_small_study_is_a_clear_error():
    sim = simulate_study((5, 4, 3), participants=6, careless=0, seed=7)
    with pytest.raises(ConfigError, match="nothing to analyse"):
        analyse(sim.ratings.iloc[:0], sim.pairwise.iloc[:0], sim.exclusions)
    one = sim.exclusions["participant"].iloc[0]
    with pytest.raises(ConfigError, match="too small.*1 included participant"):
        analyse(sim.ratings[sim.ratings["participant"] == one], sim.pairwise.iloc[:0], sim.exclusions)
    only = sim.ratings[sim.ratings["system"] == "S1"]
    with pytest.raises(ConfigError, match="1 system"):
        analyse(only, sim.pairwise.iloc[:0], sim.exclusions)
    everyone_out = sim.exclusions.assign(excluded=True)
    with pytest.raises(ConfigError, match="6 excluded"):
        analyse(sim.ratings, sim.pairwise, everyone_out)


# ---- a real study folder: design, store, the command ------------------------------------------------

QUALITY = {"knn": 6, "audio-only": 4, "random": 2}  # the systems of study_helpers.STUDY_SYSTEMS, true ratings


def _answer(page, key: dict, person: int, careless: bool) -> dict:
    """What a participant posts on a page: ratings by the system's quality, checks passed unless careless."""
    expect = page.check["expect"] if page.check else {}
    if page.kind == "audio_check":
        return {"count": expect["count"]["min"]}
    if page.kind == "questionnaire":
        return {"age": 30 + person}
    if page.kind == "rating":
        answers = {}
        for i, m in enumerate(page.media):
            if page.check and m.id == page.check["media"]:
                answers[m.id] = {p: (7 if careless else span["min"]) for p, span in expect.items()}
                answers[m.id] |= {p: answers[m.id].get(p, 4) for p in ("natural", "sync")}
            else:
                # the quality, give or take one by participant and position
                value = QUALITY[key[m.id][1]] + (person + i) % 3 - 1
                answers[m.id] = {"natural": value, "sync": value}
        return answers
    if page.kind == "pairwise":
        if page.check:
            return {"choice": 2 if careless else -2}
        left, right = (QUALITY[key[m.id][1]] for m in page.media)
        return {"choice": -2 if left > right else 2}
    return {}


@pytest.mark.slow
def test_the_command_analyses_a_study_and_excludes_who_failed_the_checks(tiny_study, tmp_path, capsys):  # noqa: F811
    from gesturekit.cli import main
    from gesturekit.study.analyse import _manifest
    from gesturekit.study.design import check_answer, init_study, participant_pages
    from gesturekit.study.store import open_store

    folder = tmp_path / "study"
    shutil.copytree(tiny_study, folder)
    design = init_study(folder, pairwise=True, attention=2)
    key = _manifest(design, None)
    store = open_store(None, folder)
    assert main(["study", "analyse", str(folder), "--rounds", "10"]) == 2  # nobody has answered yet
    assert "nothing to analyse" in capsys.readouterr().err
    tokens = []
    for person in range(7):
        careless = person == 6
        participant, _ = store.start(design.participants)
        tokens.append(participant.token)
        pages = [p for p in participant_pages(design, participant.row) if p.kind != "done"]
        for page in pages:
            answers = _answer(page, key, person, careless)
            ok = check_answer(page, answers)
            # the careless fail each attention check (they count the beeps right), the others pass
            assert ok is None or ok is not (careless and page.kind != "audio_check")
            got = store.submit(
                participant.token,
                page.id,
                page.index,
                page.kind,
                answers,
                [],
                1.0,
                failed_check=ok is False,
                max_failures=design.max_failures,
                last=page is pages[-1],
            )
            if got.status != "active":
                break
    store.close()
    frames = (open_store(None, folder).responses_frame(), open_store(None, folder).participants_frame())
    table = A.exclusions(design, frames)
    assert table.set_index("participant").loc[tokens[6], "excluded"]
    assert table.set_index("participant").loc[tokens[6], "failed_checks"] == 2
    assert not table.set_index("participant").loc[tokens[:6], "excluded"].any()
    ratings = A.ratings_table(design, frames)
    assert set(ratings["system"]) == set(QUALITY) and set(ratings["prompt"]) == {"natural", "sync"}
    assert set(A.pairwise_table(design, frames)["system_left"]) <= set(QUALITY)

    assert main(["study", "analyse", str(folder), "--rounds", "200"]) == 0
    printed = capsys.readouterr().out
    assert (
        "7 started, 0 answered nothing, 1 excluded by the checks, 0 with no rating or pairwise answer, 6 analysed"
    ) in printed
    out = folder / "analysis"
    report = (out / "report.md").read_text()
    assert all(s in report for s in QUALITY)
    summary = pd.read_csv(out / "summary.csv")
    assert list(summary.loc[summary["prompt"] == "all", "system"]) == ["knn", "audio-only", "random"]
    bt = pd.read_csv(out / "bradley_terry.csv")
    assert list(bt["system"]) == ["knn", "audio-only", "random"]
    excluded = pd.read_csv(out / "participants.csv")
    assert excluded["excluded"].sum() == 1
    # not replaced without --force: the command says so and leaves the report
    assert main(["study", "analyse", str(folder), "--rounds", "200"]) == 2
    assert "--force" in capsys.readouterr().err
    assert (out / "report.md").read_text() == report
    # the same responses as a CSV (as study import-hemvip writes them) give the same analysis
    from gesturekit.study.hemvip import write_responses_csv

    write_responses_csv(frames[0], tmp_path / "responses.csv")
    again = tmp_path / "again"
    assert (
        main(
            [
                "study",
                "analyse",
                str(folder),
                "--responses",
                str(tmp_path / "responses.csv"),
                "--out",
                str(again),
                "--rounds",
                "200",
            ]
        )
        == 0
    )
    pd.testing.assert_frame_equal(pd.read_csv(again / "summary.csv"), summary)
    pd.testing.assert_frame_equal(pd.read_csv(again / "tests.csv"), pd.read_csv(out / "tests.csv"))
