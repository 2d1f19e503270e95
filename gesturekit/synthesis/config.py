"""The options of a synthesis: :class:`SynthesisConfig`, saved with every output.

It sits below the stages (:mod:`gesturekit.synthesis.synthesizer`), which read it, and
:mod:`gesturekit.synthesis`, which re-exports it with the entry points.
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from .._config import config_from_dict, config_to_dict, option, option_of
from ..blend import BLEND_MODES, KEEP_BELOW_HZ
from ..control import ControlTrack, parse_control
from ..database import normalise_exclusions
from ..errors import ConfigError
from ..search import SearchConfig
from ..search.types import RENAMED_SEARCH_KEYS, renamed_search_keys

__all__ = ["PAPER_SETTINGS", "SEARCH_OPTIONS", "SynthesisConfig"]


#: The settings of Habibie et al. 2022: option -> (the paper's value, how a value is written,
#: the paper's value as written after it). ``refiner_keep_hz`` counts only when a refiner is
#: applied (the paper uses the refiner's output as it is).
PAPER_SETTINGS = {
    "k": (0, "k = {}", "0"),
    "segment": (8, "N = {}", "8"),
    "init": ("random", "initial pose: {}", "random"),
    "blend": ("none", "blending: {}", "none"),
    "mask_rule": ("ends", "control held at: {}", "ends"),
    "refiner_keep_hz": (0.0, "k-NN motion kept below {:g} Hz", "0: the refiner's output as it is"),
}


#: The options of :class:`SynthesisConfig` that belong to its search (:class:`SearchConfig`);
#: the saved form lists them beside the others, as it always has.
SEARCH_OPTIONS = ("k", "segment", "record", "seed", "mask_rule", "pins")


@dataclass(frozen=True, init=False)
class SynthesisConfig:
    """Every option of a synthesis; saved with every output.

    The search's options live in ``search`` (a :class:`SearchConfig`) and are read
    through it; ``k``, ``segment``, ``record``, ``seed``, ``mask_rule`` and ``pins`` are
    accepted as keywords (and by :func:`dataclasses.replace`) and read as attributes,
    both passing through to ``search``.

    Parameters
    ----------
    search : SearchConfig, optional
        k, N (``segment``), recorded candidates (``record``), seed, mask rule and pins.
        Its ``init_pose`` must be ``"random"``: the initial pose is chosen by ``init``.
    init : {"random", "rest"}
        ``random``: a random database frame that satisfies the first step's control
        (the authors' choice); ``rest``: the database's rest pose (see :func:`~gesturekit.search.plan.rest_pose_frame`).
    blend : {"none", "offset"}
        ``none`` is the paper (the refiner smooths); ``offset`` fades each join over ``blend_frames``.
    blend_frames : int
    control : str or ControlTrack
        The control track, e.g. ``"0-3:left_hand=low,3-6:speed=slow"`` (seconds); kept as its
        text, and parsed once (:attr:`control_track`).
    exclude_takes : tuple of str
        Database takes the search must not use (e.g. the query's own take).
    exclude_ranges : tuple of (str, float, float)
        (take, start_s, end_s) stretches the search must not use.
    refiner_keep_hz : float
        With a refiner: keep the k-NN motion's content slower than this (Hz) and take
        the faster content from the refiner (see :func:`gesturekit.blend.keep_slow`),
        so controls of hand height, width and symmetry survive refinement; 0: the
        refiner's output as it is (the paper).
    k, segment, record, seed, mask_rule, pins
        The options of ``search`` (see :class:`SearchConfig`); given, they replace its values.
    """

    search: SearchConfig = field(default_factory=SearchConfig)
    init: str = option(
        "random",
        help="initial pose: a random admissible database frame (the paper) or the rest pose",
        choices=("random", "rest"),
        flag="--init-pose",
    )
    blend: str = option(
        "none", help="none: the paper's hard joins; offset: a short fade at each join (ours)", choices=BLEND_MODES
    )
    blend_frames: int = option(4, help="frames of the fade at each join (blend offset)", low=1, unit="frames")
    control: str = ""
    exclude_takes: tuple = ()
    exclude_ranges: tuple = ()
    refiner_keep_hz: float = option(
        KEEP_BELOW_HZ,
        help="keep the k-NN motion's content slower than HZ (hand height, width, symmetry: the controls) and "
        "take the faster content from the refiner; 0: the refiner's output as it is (the paper)",
        low=0.0,
        unit="Hz",
        metavar="HZ",
        step=0.5,
        limit=lambda db: db.fps / 2,  # above the Nyquist frequency the k-NN motion is kept whole
    )
    if TYPE_CHECKING:  # set by __init__: the control parsed once (not an option of its own)
        _track: ControlTrack = field(init=False, repr=False, compare=False)

    def __init__(
        self,
        search: SearchConfig | None = None,
        *,
        init: str = "random",
        blend: str = "none",
        blend_frames: int = 4,
        control: str | ControlTrack = "",
        exclude_takes: Sequence[str] = (),
        exclude_ranges: Sequence[tuple[str, float, float]] = (),
        refiner_keep_hz: float = KEEP_BELOW_HZ,
        **search_options: Any,
    ) -> None:
        unknown = set(search_options) - set(SEARCH_OPTIONS)
        if unknown:
            raise ConfigError(f"unknown synthesis options: {', '.join(sorted(unknown))}")
        search = SearchConfig() if search is None else search
        if not isinstance(search, SearchConfig):
            raise ConfigError(f"search must be a SearchConfig, got {type(search).__name__}")
        if search_options:
            search = replace(search, **search_options)
        if search.init_pose != "random":
            raise ConfigError(
                "the initial pose of a synthesis is chosen by init ('random' or 'rest'), not by search.init_pose"
            )
        hz = refiner_keep_hz
        if (
            isinstance(hz, bool)
            or not isinstance(hz, numbers.Real)
            or not (np.isfinite(hz) and hz >= option_of(SynthesisConfig, "refiner_keep_hz").low)
        ):
            raise ConfigError(f"refiner_keep_hz must be a frequency >= 0 (0: off), got {hz!r}")
        if init not in (option_of(SynthesisConfig, "init").choices or ()):
            raise ConfigError(f"init must be 'random' or 'rest', got {init!r}")
        if blend not in (option_of(SynthesisConfig, "blend").choices or ()):
            raise ConfigError(f"blend must be one of {', '.join(BLEND_MODES)}, got {blend!r}")
        if not isinstance(blend_frames, int) or blend_frames < option_of(SynthesisConfig, "blend_frames").low:
            raise ConfigError(f"blend_frames must be a positive integer, got {blend_frames!r}")
        track = control if isinstance(control, ControlTrack) else parse_control(control)  # validates
        takes, ranges = normalise_exclusions(exclude_takes, exclude_ranges)
        for name, value in (
            ("search", search),
            ("init", init),
            ("blend", blend),
            ("blend_frames", blend_frames),
            ("control", track.to_text()),
            ("exclude_takes", takes),
            ("exclude_ranges", ranges),
            ("refiner_keep_hz", float(hz)),
            ("_track", track),
        ):
            object.__setattr__(self, name, value)

    # the search's options, read through ``search`` (one source of truth)
    k = property(lambda self: self.search.k, doc="Take the k-th best of the combined ranking (0 = best).")
    segment = property(lambda self: self.search.segment, doc="Frames per search step, N (8 in the paper).")
    record = property(lambda self: self.search.record, doc="Candidates per step recorded for inspection.")
    seed = property(lambda self: self.search.seed, doc="Seed of the random initial pose.")
    mask_rule = property(lambda self: self.search.mask_rule, doc="Where a control must hold in a window.")
    pins = property(lambda self: self.search.pins, doc="Step -> (clip, start): forced choices.")

    @property
    def control_track(self) -> ControlTrack:
        """The control track, parsed once when the configuration was made."""
        return self._track

    def to_dict(self) -> dict:
        """A JSON-able dict, the search's options beside the others (the layout of every
        version's saved form); :meth:`from_dict` reads it back."""
        search = self.search.to_dict()
        out = {name: search[name] for name in ("k", "segment", "record", "seed")}
        out["init"] = self.init
        out["mask_rule"] = search["mask_rule"]
        out.update(config_to_dict(self, exclude=("search", "init", "refiner_keep_hz")))
        out["pins"] = search["pins"]
        out["refiner_keep_hz"] = self.refiner_keep_hz
        return out

    @classmethod
    def from_dict(cls, d: Mapping) -> SynthesisConfig:
        """Inverse of :meth:`to_dict`; also reads a nested ``"search"`` object, and the names
        earlier versions saved N and the recorded candidates under (``step``, ``topk``).

        Raises
        ------
        ConfigError
            Unknown options.
        """
        if not isinstance(d, Mapping):
            raise ConfigError(f"synthesis options must be a JSON object, got {type(d).__name__}")
        d = dict(d)
        search = dict(d.pop("search", None) or {})
        # earlier versions' flat "step" and "topk" belong to the search too ("init" is ours)
        flat = [*SEARCH_OPTIONS, *(old for old in RENAMED_SEARCH_KEYS if old != "init")]
        search.update({name: d.pop(name) for name in flat if name in d})
        search = renamed_search_keys(search)
        d["search"] = SearchConfig.from_dict(search)
        return config_from_dict(cls, d, what="synthesis options")

    def paper_differences(self, *, refined: bool) -> list[str]:
        """The settings that differ from the paper's (:data:`PAPER_SETTINGS`), as text.

        Parameters
        ----------
        refined : bool
            Whether a refiner is applied (``refiner_keep_hz`` counts only then).

        Returns
        -------
        list of str
            E.g. ``["N = 6 (paper 8)"]``; empty when the search is the paper's.
        """
        out = []
        for name, (paper, form, paper_text) in PAPER_SETTINGS.items():
            value = getattr(self, name)
            if value != paper and (refined or name != "refiner_keep_hz"):
                out.append(f"{form.format(value)} (paper {paper_text})")
        return out

    def with_control(self, control: str | ControlTrack) -> SynthesisConfig:
        """A copy with another control track (its text, or the track itself)."""
        options: dict[str, Any] = {f.name: getattr(self, f.name) for f in fields(self)}
        options["control"] = control
        return SynthesisConfig(**options)

    def with_pin(self, step: int, clip: int, start: int) -> SynthesisConfig:
        """A copy with one more pinned choice (replacing any pin at that step)."""
        pins = dict(self.pins)
        pins[int(step)] = (int(clip), int(start))
        return replace(self, search=replace(self.search, pins=pins))

    def without_pin(self, step: int) -> SynthesisConfig:
        """A copy without the pinned choice at ``step`` (if any)."""
        pins = {i: v for i, v in self.pins.items() if i != int(step)}
        return replace(self, search=replace(self.search, pins=pins))
