"""The one closed loop: every run (SIL, HIL over CAN or MAVLink, the image in QEMU) steps this body against an
endpoint (:mod:`.endpoints`).

Per step ``k``: the plant hears the external scheduling signals (a plant that follows them), its outputs are
sampled (plus the plan's noise), a ``nan`` fault may replace the sample by NaN, the endpoint gets ``(y, r, s)``
and answers with the law's :class:`~gainlink.laws.Step` or nothing in time (the last command is held), and the
plant advances under the command plus the plan's disturbance for one period. Lockstep runs as fast as the endpoint
answers; real time waits for the pacer's tick (:func:`.scheduler.next_tick`), each command due by the next tick,
and ticks missed in a stall are held steps (the plant runs on under the last command; the endpoint never sees
those samples). A controller that dies or stays silent ends the run early (``reason``), as a plant that fails
does. The twins are not stepped here: they are computed from the plan after the run (:mod:`.twins`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from gainlink.errors import PlantError

from ..plants.base import Plant
from .faults import FaultInjector
from .plan import Plan
from .scheduler import SPIN_NS, Pacer, next_tick


class Stop(Exception):
    """Ends the loop early: the run is incomplete for ``reason`` after ``steps`` steps."""

    def __init__(self, reason: str, steps: int) -> None:
        super().__init__(reason)
        self.reason, self.steps = reason, steps


@dataclass(frozen=True)
class Outcome:
    """How the loop ended: the steps taken, the reason when it ended early, its wall time, the overruns of a real-time
    run, and the CPU time of the thread that ran it (the loop's own cost, whatever else the machine does)."""

    steps: int
    reason: str | None
    wall_s: float
    overruns: int
    cpu_s: float = 0.0


class ClosedLoop:
    """One run's loop (module docstring): ``plant`` (reset to the plan's start), ``endpoint``, the plan's samples
    and the faults on the samples' values (``injector.corrupt``; the endpoint applies the others)."""

    def __init__(self, *, plan: Plan, plant: Plant, endpoint, injector: FaultInjector, Ts: float, record_state: bool,
                 skip_overruns: bool = True) -> None:  # fmt: skip
        self.plan, self.plant, self.endpoint, self.injector, self.Ts = plan, plant, endpoint, injector, Ts
        self.rec = endpoint.recorder
        self.record_state = record_state  # the plant's state per step: an FMU call per step, only with the twin
        self.skip = skip_overruns
        self.follow = getattr(plant, "schedule", None)  # a plant whose dynamics follow the external signals
        self.corrupts = bool(injector.sample_faults)  # a nan fault may replace a sample
        self.disturbed = bool(plan.D.any())  # else the command goes to the plant as it is
        self.u = endpoint.safe_command()  # until the first command
        self.sigma = plan.sigma0
        self.overruns = 0
        self.period_ns = int(round(plan.period_s * 1e9))

    def run(self, progress: Callable[[int, int], None] | None) -> Outcome:
        """Run every planned step (or until the endpoint or the plant fails)."""
        N = self.plan.N
        every = max(1, N // 100)
        cpu0 = time.thread_time()
        self.t_start = time.perf_counter_ns()
        self.endpoint.begin(self.t_start)
        self.pacer = Pacer(period_ns=self.period_ns) if self.plan.realtime else None
        k, reason = 0, None
        try:
            while k < N:
                self.endpoint.peer_faults(k)
                wait_until = None
                if self.pacer is not None:
                    k, wait_until = self._next_tick(k)
                    if k >= N:
                        break
                self._step(k, wait_until)
                k += 1
                if progress is not None and k % every == 0:
                    progress(k, N)
        except Stop as stop:  # in step k: the command held there
            k, reason = stop.steps, stop.reason
            self.rec.U[k - 1], self.rec.SIGMA[k - 1] = self.u, self.sigma
        except PlantError as exc:  # in an overrun's held steps
            reason = f"plant failed at step {k}: {exc}"
        wall = (time.perf_counter_ns() - self.t_start) / 1e9
        cpu = time.thread_time() - cpu0
        if progress is not None:
            progress(k, N)
        return Outcome(steps=k, reason=reason, wall_s=wall, overruns=self.overruns, cpu_s=cpu)

    def _next_tick(self, k: int) -> tuple[int, int]:
        """Wait for the pacer's next tick; returns the step to run and when its command is due (absolute ns).

        Ticks that passed while the loop was stalled (an overrun) are held steps of the plant: it runs on under the
        last command, as a real one would, and each is a deadline miss.
        """
        pacer = self.pacer
        offset = pacer.start_ns - self.t_start
        start, N = k, self.plan.N
        k, due_rel, woke_rel = next_tick(
            pacer, k, steps=N, skip=self.skip, hold=lambda j, due: self._hold(j, due + offset)
        )
        self.overruns += k - start
        if k >= N:
            return k, 0
        self.rec.DUE[k] = due_rel + offset
        self.rec.TICK[k] = woke_rel + offset
        return k, pacer.start_ns + due_rel + self.period_ns - SPIN_NS // 2

    def _hold(self, j: int, due: int) -> None:
        """A tick missed in an overrun: the plant runs on under the last command (never sent: no jitter, a miss)."""
        rec = self.rec
        if self.follow is not None:
            self.follow(self.plan.S[j])
        rec.Y[j] = self.plant.outputs() + self.plan.noise[j]
        rec.U[j], rec.SIGMA[j], rec.DUE[j], rec.TICK[j] = self.u, self.sigma, due, np.nan
        self.plant.advance(u=self.u + self.plan.D[j], dt=self.Ts)

    def _step(self, k: int, wait_until: int | None) -> None:
        """Sample, hand the sample to the endpoint, take its answer, and advance the plant by one period."""
        rec, plan = self.rec, self.plan
        if self.follow is not None:
            self.follow(plan.S[k])
        y = self.plant.outputs() + plan.noise[k]
        rec.Y[k] = y
        if self.record_state:
            rec.X[k] = self.plant.state()
        if self.corrupts:
            sent_y = self.injector.corrupt(k, y)
            rec.NAN[k] = sent_y is not y
            y = sent_y
        sent = self.endpoint.send(k, y, plan.R[k], plan.S[k])
        if wait_until is None:
            rec.TICK[k] = sent - self.t_start
        step = self.endpoint.receive(k, deadline=wait_until)
        if step is not None:
            self.u, self.sigma = step.u, step.sigma
            rec.GOT[k], rec.SATBITS[k], rec.FLAGS[k] = True, step.sat, step.flags
        else:
            self.endpoint.no_answer(k)
        rec.U[k], rec.SIGMA[k] = self.u, self.sigma
        try:
            self.plant.advance(u=self.u + plan.D[k] if self.disturbed else self.u, dt=self.Ts)
        except PlantError as exc:
            raise Stop(f"plant failed at step {k}: {exc}", k + 1) from None
