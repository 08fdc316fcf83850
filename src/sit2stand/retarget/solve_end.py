"""When a whole-rise solve ends (:mod:`sit2stand.retarget.whole_rise`): Crocoddyl's own gradient test rarely ends a
box-FDDP solve of the rise (docs/method.md), so a callback ends it on the cost's plateau or on its solution's checks."""

from __future__ import annotations

from collections.abc import Callable

import crocoddyl
import numpy as np

Progress = Callable[[str], None]
"""A progress callback: one line of text per call."""
PROGRESS_EVERY = 10
"""Iterations between two progress lines of a solve."""


class SolveEnd(crocoddyl.CallbackAbstract):
    """Ends a Crocoddyl solve once its rollout is feasible and its cost fell less than ``share`` over the last
    ``iterations`` iterations, or sooner once its solution passed its checks (``passes``:
    :meth:`WholeRiseProblem.passes`) over the last ``passed_iterations`` and its cost fell less than ``passed_share``
    over them. The solver calls its callbacks just before its own stopping test, which then passes (its threshold
    raised): box-FDDP's own gradient test rarely ends a solve (docs/method.md). ``progress``: told the cost every
    ``PROGRESS_EVERY`` iterations."""

    def __init__(self, iterations: int, share: float, progress: Progress | None = None,
                 passes: Callable[[object], bool] | None = None, passed_iterations: int = 0,
                 passed_share: float = 0.0) -> None:
        super().__init__()
        self.iterations, self.share, self.progress, self.passes = int(iterations), float(share), progress, passes
        self.passed_iterations, self.passed_share, self.passed, self.costs = int(passed_iterations), passed_share, 0, []

    def __call__(self, solver) -> None:
        self.costs.append(float(solver.cost) if solver.isFeasible else np.inf)
        if self.progress is not None and len(self.costs) % PROGRESS_EVERY == 0:
            self.progress(f"  iteration {len(self.costs)}: cost {solver.cost:.4g}"
                          f"{'' if solver.isFeasible else ', gaps still open'}")
        if self.passes is not None and self.passed_iterations > 0:
            self.passed = self.passed + 1 if self.passes(solver) else 0
        if self._flat(self.iterations, self.share) or (
                self.passed >= self.passed_iterations > 0 and self._flat(self.passed_iterations, self.passed_share)):
            solver.th_stop = np.inf

    def _flat(self, iterations: int, share: float) -> bool:
        """Whether the cost fell less than ``share`` over the last ``iterations`` iterations, feasible throughout."""
        if len(self.costs) <= iterations:
            return False
        before, now = self.costs[-1 - iterations], self.costs[-1]
        return bool(np.isfinite(before) and before - now <= share * abs(before))
