"""gesturekit's tests (folders by layer; tests/conftest.py holds the shared fixtures).

numba (librosa's onset peak picking, our search loops) caches compiled code on disk; two test
workers compiling the same function at once can read each other's half-written cache and crash.
Each test worker (xdist's gw0, gw1, ...; "main" without xdist) of each checkout gets its own cache
folder, kept between runs so that a run does not compile again what the last one compiled. It is
set here, before anything imports numba; a worker inherits the controller's environment, so a
folder set by this file is replaced by the worker's own, one set by the user is kept.
"""

import hashlib
import os
import tempfile
from pathlib import Path

_OURS = "GESTUREKIT_TESTS_NUMBA_CACHE"
if os.environ.get("NUMBA_CACHE_DIR") in (None, os.environ.get(_OURS)):
    _checkout = hashlib.sha256(str(Path(__file__).resolve().parents[1]).encode()).hexdigest()[:10]
    _worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    _dir = os.path.join(tempfile.gettempdir(), f"gesturekit-tests-numba-{os.getuid()}-{_checkout}-{_worker}")
    os.environ["NUMBA_CACHE_DIR"] = os.environ[_OURS] = _dir
