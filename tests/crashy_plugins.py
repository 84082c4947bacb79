"""An ADS that fails on purpose, for the crash-isolation and distributed tests.

Loaded as ``--ads crashy_plugins:FailingADS`` (the module is on the tests' path,
which the simulation host and the test's Dask workers inherit).
"""

from __future__ import annotations

import os
import sys
import time
from typing import Literal

from ego.ads import ReferenceADS


class FailingADS(ReferenceADS):
    """The reference ADS until simulated time ``at``, then it aborts, hangs, raises, exits or writes to stdout."""

    name = "failing"

    class Options(ReferenceADS.Options):
        failure: Literal["abort", "hang", "spin", "raise", "exit", "stdout", "none"] = "abort"
        at: float = 1.0  # [s] simulated time

    def step(self, obs):
        if obs.t >= self.options.at:
            if self.options.failure == "abort":
                os.abort()  # what a segfault in native code looks like to the caller
            if self.options.failure == "hang":
                time.sleep(3600)
            if self.options.failure == "spin":
                sum(range(10**13))  # a hang that never releases the GIL
            if self.options.failure == "raise":
                raise ZeroDivisionError("planned failure")
            if self.options.failure == "exit":
                sys.exit(3)
            if self.options.failure == "stdout" and not getattr(self, "_noisy", False):
                self._noisy = True  # then drive on normally
                print("print from a plugin")
                os.write(1, b"raw bytes on fd 1\n")
                os.system("echo a subprocess writing to stdout")
        return super().step(obs)
