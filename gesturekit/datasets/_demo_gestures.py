"""The generated demo speaker's gesture plan: keyposes of each arm, timed to the speech.

Gesture phrases over the spoken phrases: a preparation, strokes that end on
the vowel onsets of stressed syllables, rebounds and holds, and a retraction
to the rest pose in long pauses. Part of :mod:`gesturekit.datasets.synthetic`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._demo_body import CURL, DEV, FLEX, POSE_DIM, ROLL, SPREAD, SWIVEL, WRIST, reachable, unit
from ._demo_speech import Speech, draw

# ---------------------------------------------------------------------------------------------
# gesture plan: keyposes per arm
# ---------------------------------------------------------------------------------------------

_HANDSHAPES = np.array(
    [  # curls (thumb, index, middle, ring, pinky), spread
        (0.1, 0.05, 0.05, 0.08, 0.1, 0.9),  # open
        (0.35, 0.3, 0.38, 0.45, 0.5, 0.4),  # relaxed
        (0.6, 0.02, 0.85, 0.9, 0.92, 0.2),  # pointing
        (0.75, 0.9, 0.92, 0.92, 0.9, 0.1),  # fist
        (0.6, 0.55, 0.4, 0.5, 0.55, 0.3),  # pinch
    ]
)
_HANDSHAPE_P = np.array([0.3, 0.3, 0.15, 0.1, 0.15])

_HEIGHTS = ((0.06, 0.2), (0.22, 0.34), (0.38, 0.58))  # low, middle, high wrist height (m)
_HEIGHT_P = np.array([0.38, 0.24, 0.38])
_WIDTHS = ((0.04, 0.13), (0.17, 0.27), (0.33, 0.46))  # narrow, middle, wide (m from the midline)
_WIDTH_P = np.array([0.35, 0.3, 0.35])
_MODES = ("symmetric", "asymmetric", "left", "right")
_MODE_P = np.array([0.4, 0.2, 0.2, 0.2])
_STROKE_KIND_P = np.array([0.5, 0.2, 0.2, 0.1])  # down, out, forward, across
_PALM_ROLLS = (-1.1, -0.5, 0.0, 0.6)  # forearm roll of a gesture: palm up, up-in, in, down (rad)


def _rest_pose(rng: np.random.Generator) -> np.ndarray:
    """Hands low beside the hips, palms inward, fingers relaxed (with a little variation)."""
    p = np.zeros(POSE_DIM)
    p[WRIST] = (0.21, -0.08, 0.05) + rng.normal(0.0, 0.012, 3)
    p[SWIVEL] = 0.1
    p[ROLL] = rng.normal(-0.1, 0.1)
    p[FLEX] = 0.1
    p[CURL] = (0.3, 0.3, 0.38, 0.45, 0.5)
    p[SPREAD] = 0.3
    return p


# the speaker's gesture space: a wrist keeps this far (m) to its own side of the body's midline, and
# further the higher it is, so the hands stay in front of the torso, go up beside the head rather
# than over the face, and never cross; the bound is convex, so the straight moves between keyposes
# keep to it too
_MIDLINE_GAP = 0.09
_WIDEN_ABOVE, _WIDEN_RATE = 0.30, 1.1  # above this wrist height (m) the gap grows by this much per metre
# and a wrist nearer the midline keeps further forward, clear of the belly and chest: z + _LEAN x >= _FRONT
_FRONT, _LEAN = 0.214, 0.6


def in_gesture_space(pose: np.ndarray) -> np.ndarray:
    """A copy of ``pose`` with the wrist target moved outward into the speaker's gesture space."""
    pose = pose.copy()
    x, y, z = pose[WRIST]
    x = max(x, _MIDLINE_GAP + _WIDEN_RATE * max(0.0, y - _WIDEN_ABOVE))
    pose[WRIST] = (x, y, max(z, _FRONT - _LEAN * x))
    return pose


_MAX_SPEED = 2.3  # fastest wrist movement of a keypose move, m/s (peak)
_MIN_JERK_PEAK = 1.875  # peak speed of a minimum-jerk move over its mean speed


class ArmTrack:
    """Keyposes of one arm; consecutive keyposes are joined by minimum-jerk moves."""

    def __init__(self, rest: np.ndarray):
        self.times = [0.0]
        self.poses = [in_gesture_space(reachable(rest))]
        self.pending_retraction: float | None = None  # earliest start of an owed retraction

    @property
    def last_time(self) -> float:
        return self.times[-1]

    @property
    def last_pose(self) -> np.ndarray:
        return self.poses[-1]

    def move(self, t0: float, t1: float, pose: np.ndarray) -> None:
        """Hold the current pose until ``t0``, then move to ``pose``, arriving at ``t1``.

        A wrist target beyond comfortable reach is pulled towards the shoulder, so that the
        straight-line moves between keyposes stay inside the arm's reach, then moved outward
        into the gesture space (:func:`in_gesture_space`), and a move that would be faster than
        :data:`_MAX_SPEED` at its peak stops short (towards a point inside both bounds).
        """
        t0 = max(t0, self.times[-1])
        t1 = max(t1, t0 + 0.05)
        pose = in_gesture_space(reachable(pose))
        step = pose[WRIST] - self.poses[-1][WRIST]
        longest = _MAX_SPEED * (t1 - t0) / _MIN_JERK_PEAK
        if np.linalg.norm(step) > longest:
            pose[WRIST] = self.poses[-1][WRIST] + step * (longest / np.linalg.norm(step))
        if t0 > self.times[-1] + 1e-6:
            self.times.append(t0)
            self.poses.append(self.poses[-1])
        self.times.append(t1)
        self.poses.append(pose)


@dataclass
class GesturePlan:
    arms: tuple[ArmTrack, ArmTrack]  # left, right (both in the left arm's convention)
    stroke_times: np.ndarray
    stroke_stress: np.ndarray
    stroke_hands: tuple[str, ...]
    gesture_phrases: np.ndarray
    gesture_modes: tuple[str, ...]


def _home_pose(rng, height_class: int, width_class: int, shape: int, rest: np.ndarray) -> np.ndarray:
    """The centre of a gesture phrase's movements for one arm."""
    p = rest.copy()
    y = rng.uniform(*_HEIGHTS[height_class])
    x = rng.uniform(*_WIDTHS[width_class])
    z = rng.uniform(0.2, 0.36) - 0.12 * (width_class == 2) - 0.05 * (height_class == 0)
    p[WRIST] = (x, y, z)
    p[SWIVEL] = rng.uniform(-0.2, 0.5) + 0.3 * (width_class == 2)
    p[ROLL] = _PALM_ROLLS[rng.integers(len(_PALM_ROLLS))] + rng.normal(0.0, 0.15)
    p[FLEX] = rng.uniform(-0.3, 0.3)
    p[DEV] = rng.uniform(-0.15, 0.15)
    hs = _HANDSHAPES[shape]
    p[CURL] = np.clip(hs[:5] + rng.normal(0.0, 0.06, 5), 0.0, 1.0)
    p[SPREAD] = np.clip(hs[5] + rng.normal(0.0, 0.1), 0.0, 1.0)
    return p


def _stroke_direction(rng) -> np.ndarray:
    """Unit direction of a stroke (left-arm convention): mostly down, also out, forward, across."""
    kind = draw(rng, _STROKE_KIND_P)
    base = np.array([(0.0, -1.0, 0.35), (1.0, -0.3, 0.2), (0.1, -0.3, 1.0), (-1.0, -0.2, 0.3)][kind])
    return unit(base + rng.normal(0.0, 0.25, 3))


def plan_gestures(speech: Speech, rng: np.random.Generator, duration: float) -> GesturePlan:
    """Gesture phrases over the speech phrases: preparation, strokes on stresses, retraction."""
    rests = (_rest_pose(rng), _rest_pose(rng))
    arms = (ArmTrack(rests[0]), ArmTrack(rests[1]))
    stroke_times, stroke_stress, stroke_hands = [], [], []
    g_phrases, g_modes = [], []

    def settle(i: int, until: float) -> None:
        """Retract arm ``i`` after its last stroke, as far as the time before ``until`` allows."""
        arm = arms[i]
        if arm.pending_retraction is None:
            return
        t0 = max(arm.pending_retraction, arm.last_time)
        arm.pending_retraction = None
        avail = until - t0
        if avail >= 0.8:  # all the way down to the rest pose, unhurried
            arm.move(t0, t0 + min(rng.uniform(0.7, 1.0), avail - 0.1), _rest_pose(rng))
        # else: too short a pause to go down and come back up; the hands hold

    for p in range(len(speech.phrases)):
        a = speech.arousal[p]
        in_phrase = (speech.syl_phrase == p) & speech.syl_stressed
        stresses = speech.syl_nucleus[in_phrase]
        emphasis = speech.syl_emphasis[in_phrase]
        if rng.random() > 0.55 + a or len(stresses) == 0:  # calm phrases sometimes go ungestured
            settle(0, np.inf)
            settle(1, np.inf)
            continue
        mode = _MODES[draw(rng, _MODE_P)]
        used = {"symmetric": (0, 1), "asymmetric": (0, 1), "left": (0,), "right": (1,)}[mode]
        for i in (0, 1):
            if i not in used:
                settle(i, np.inf)
        fast = rng.random() < 0.1 + 0.8 * a
        # Gesture phases keep to the syllables. A stroke ends on the stressed vowel onset: the hand
        # stops and turns there (a velocity minimum), so the stroke's fast part precedes the
        # stress. It starts on the vowel onset of a syllable before, and the hand rebounds, about
        # as briskly, to where the next stroke starts (or this one started), arriving on a later
        # vowel onset; where the syllables give no fitting length, a phase takes its own.
        g = np.flatnonzero(in_phrase)
        nuc, syl_p = speech.syl_nucleus, speech.syl_phrase
        shortest, longest = (0.18, 0.34) if fast else (0.24, 0.48)
        ends = stresses + rng.uniform(-0.02, 0.02, len(g))
        durs = rng.uniform(shortest, longest, len(g))
        jitter = rng.uniform(-0.02, 0.02, (2, len(g)))
        starts, rebounds = ends - durs, ends + durs
        for k, j in enumerate(g):
            for back in (1, 2):
                if j - back >= 0 and syl_p[j - back] == p and shortest <= ends[k] - nuc[j - back] <= longest:
                    starts[k] = nuc[j - back] + jitter[0, k]
                    break
            for ahead in (1, 2):
                if j + ahead < len(nuc) and syl_p[j + ahead] == p and shortest <= nuc[j + ahead] - ends[k] <= longest:
                    rebounds[k] = nuc[j + ahead] + jitter[1, k]
                    break
        chosen, last_end = [], -np.inf
        for k in range(len(g)):
            # a stroke too soon after the last one to leave room for a rebound starts straight from
            # its end, back the way the hand came (a beat back)
            if ends[k] - last_end >= shortest and ends[k] < duration - 0.1:
                chosen.append(k)
                last_end = ends[k]
        height, width = draw(rng, _HEIGHT_P), draw(rng, _WIDTH_P)
        home = {used[0]: _home_pose(rng, height, width, draw(rng, _HANDSHAPE_P), rests[used[0]])}
        if mode == "symmetric":
            home[1] = home[0].copy()
            home[1][WRIST] += rng.normal(0.0, 0.01, 3)
        elif mode == "asymmetric":
            # the other hand at another height and width, doing less
            h2, w2 = (height + rng.integers(1, 3)) % 3, (width + rng.integers(1, 3)) % 3
            home[1] = _home_pose(rng, h2, w2, draw(rng, _HANDSHAPE_P), rests[1])
        # hands start moving at the earliest a little before the speech does, and after what
        # they did before; drop strokes until a preparation fits
        earliest = max([arms[i].last_time + 0.05 for i in used] + [speech.phrases[p, 0] - 0.3, 0.0])
        while chosen and starts[chosen[0]] - earliest < 0.3:
            chosen.pop(0)
        if not chosen:
            for i in used:
                settle(i, np.inf)
            continue
        first_start = starts[chosen[0]]
        # through a short pause the hands stay up; in a longer one they go down to rest if that
        # leaves time for an unhurried preparation
        silence = speech.phrases[p, 0] - (speech.phrases[p - 1, 1] if p > 0 else 0.0)
        for i in used:
            if silence >= 0.6:
                settle(i, first_start - 0.8)
            arms[i].pending_retraction = None
        # the preparation takes longer the further the hand travels
        travel = max(float(np.linalg.norm(home[i][WRIST] - arms[i].last_pose[WRIST])) for i in used)
        prep_dur = float(np.clip(travel / (rng.uniform(0.7, 1.0) * (1.3 if fast else 1.0)), 0.3, 0.8))
        earliest = max([earliest] + [arms[i].last_time + 0.05 for i in used])
        prep_start = max(earliest, first_start - prep_dur)
        dominant = int(rng.integers(2)) if mode == "asymmetric" else used[0]
        scale = (0.12 + 0.26 * a) if fast else (0.08 + 0.12 * a)
        # repeated beats of a gesture phrase go much the same way (the hands of a symmetric phrase
        # mirror each other; the secondary hand of an asymmetric one goes its own way)
        phrase_dir = {i: _stroke_direction(rng) for i in used}
        # a hand's last stroke direction and start pose, set by its first stroke (read only after one)
        prev_dir: dict[int, np.ndarray] = {}
        prev_start: dict[int, np.ndarray] = {}
        rebound_at = {i: 0.0 for i in used}  # when the hand's rebound from its last stroke is due to end
        at_stroke_end = {i: False for i in used}  # the hand has just ended a stroke and not yet rebounded
        for n, k in enumerate(chosen):
            s1 = ends[k]
            direction = unit(phrase_dir[dominant] + rng.normal(0.0, 0.25, 3))
            amp = scale * emphasis[k] ** 2 * rng.uniform(0.85, 1.15)  # louder syllable, bigger stroke
            hands = []
            for i in used:
                arm = arms[i]
                s0 = starts[k]
                if i != dominant and mode == "asymmetric":
                    if rng.random() > 0.4:
                        if n == 0:  # the secondary hand still takes its position
                            arm.move(prep_start, s1, home[i])
                        continue
                    d_i, amp_i = unit(phrase_dir[i] + rng.normal(0.0, 0.25, 3)), 0.5 * amp
                else:
                    d_i, amp_i = direction, amp
                beat_back = at_stroke_end[i] and s0 - arm.last_time < shortest
                if beat_back:
                    d_i = unit(-prev_dir[i] + rng.normal(0.0, 0.2, 3))
                start_pose = home[i].copy()
                start_pose[WRIST] -= 0.5 * amp_i * d_i
                start_pose[FLEX] -= 0.15
                end_pose = home[i].copy()
                end_pose[WRIST] += 0.5 * amp_i * d_i
                end_pose[FLEX] += 0.2  # the hand flicks with the beat
                end_pose[CURL] = np.clip(end_pose[CURL] - 0.08, 0.0, 1.0)
                if arm.last_time <= prep_start:  # preparation from wherever the hand rests
                    arm.move(prep_start, s0, start_pose)
                elif beat_back:  # no room for a rebound: straight back from the last stroke's end
                    s0 = arm.last_time
                elif at_stroke_end[i]:
                    # rebound to this stroke's start, then hold there until the stroke
                    arm.move(arm.last_time, min(rebound_at[i], s0), start_pose)
                    at_stroke_end[i] = False
                if s1 - s0 < 0.1 or s0 < arm.last_time:  # this hand is still busy; it sits this stroke out
                    continue
                arm.move(s0, s1, end_pose)
                prev_dir[i], prev_start[i], rebound_at[i] = d_i, start_pose, rebounds[k]
                at_stroke_end[i] = True
                hands.append(i)
            if hands:
                stroke_times.append(ends[k])
                stroke_stress.append(stresses[k])
                stroke_hands.append("both" if len(hands) == 2 else ("left", "right")[hands[0]])
        g_phrases.append((prep_start, max(arms[i].last_time for i in used)))
        g_modes.append(mode)
        phrase_end = speech.phrases[p, 1]
        for i in used:
            arm = arms[i]
            if at_stroke_end[i]:
                # after the last stroke the hand rebounds to where the stroke began and holds until
                # the speech pauses; the retraction comes in the pause
                arm.move(arm.last_time, rebound_at[i], prev_start[i])
            arm.pending_retraction = max(arm.last_time + rng.uniform(0.1, 0.3), phrase_end + rng.uniform(0.05, 0.2))
    settle(0, np.inf)
    settle(1, np.inf)
    return GesturePlan(
        arms=arms,
        stroke_times=np.array(stroke_times, dtype=np.float64),
        stroke_stress=np.array(stroke_stress, dtype=np.float64),
        stroke_hands=tuple(stroke_hands),
        gesture_phrases=np.array(g_phrases, dtype=np.float64).reshape(-1, 2),
        gesture_modes=tuple(g_modes),
    )
