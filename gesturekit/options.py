"""Every option's one source: the metadata of the configuration dataclasses' fields.

An option is a field declared with :func:`option` (its help, bounds, choices and unit);
the command line's flags and the app's widgets read it from there (see :func:`widget_limits`).

The configurations so declared: :class:`~gesturekit.search.SearchConfig`,
:class:`~gesturekit.synthesis.SynthesisConfig`, :class:`~gesturekit.refine.train.TrainConfig`,
:class:`~gesturekit.study.config.StudyConfig`, :class:`~gesturekit.evaluate.run.EvaluationConfig`,
:class:`~gesturekit.evaluate.fgd.FGDConfig` and :class:`~gesturekit.database.BuildConfig`.
"""

from __future__ import annotations

from ._config import Option, check_option, default_of, option, option_of, options_config, options_of, widget_limits

__all__ = [
    "Option",
    "option",
    "options_of",
    "option_of",
    "default_of",
    "check_option",
    "widget_limits",
    "options_config",
]
