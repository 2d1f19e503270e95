"""Objective evaluation: metrics (pure functions), baselines, the FGD autoencoder, and the runner.

- :mod:`~gesturekit.evaluate.metrics`: beat consistency, diversity, Fréchet distance, Hellinger
  distances of velocity and acceleration histograms, jerk, boundary jumps, control adherence.
- :mod:`~gesturekit.evaluate.fgd`: the motion autoencoder whose latent space FGD is measured in.
- :mod:`~gesturekit.evaluate.baselines`: the systems compared (ground truth, random segments,
  audio-only and pose-only nearest neighbours, k-NN, k-NN + cGAN).
- :mod:`~gesturekit.evaluate.run`: :func:`~gesturekit.evaluate.run.evaluate` on a held-out part of
  a database, and the CSV / markdown writers.
"""
