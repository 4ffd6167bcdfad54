"""Observers of a HIL run: what watches the run (the MCAP recorder, a live publisher, a state saver)
attaches here instead of inside the stepping loop.

An observer is called with the running `RunState` (its `master`, `case`, `topology`, `monitor`):
  - on_start(run): once, after the master is up and before the first step;
  - on_step(run, k): after step k (only if the observer overrides it: it costs every step);
  - on_span(run, span, record): after each complete span, with the convergence record of that span;
  - on_end(run): once, when stepping is over for any reason (the run folder is summarised after it).
"""
from __future__ import annotations

import numpy as np

from .channels import span_force_record


class RunObserver:
    """Does nothing; subclass and override what you need."""

    wants_steps = False  # set by __init_subclass__ when on_step is overridden

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        cls.wants_steps = cls.on_step is not RunObserver.on_step

    def on_start(self, run) -> None:
        """Called once, after the master is up and before the first step."""
        pass

    def on_step(self, run, k: int) -> None:
        """Called after step k (only for observers that override it)."""
        pass

    def on_span(self, run, span: int, record: dict) -> None:
        """Called after each complete span with its convergence record."""
        pass

    def on_end(self, run) -> None:
        """Called once when stepping is over, for any reason."""
        pass


def group_block(master, groups: dict, topic: str, start: int, stop: int) -> np.ndarray:
    """Columns of a logged group for steps start..stop-1: an FMU's outputs and inputs, or the pacer's."""
    if topic == "/master":
        pacer = master.pacer
        return np.column_stack([pacer.lateness_ns[start:stop] / 1e3, pacer.duration_ns[start:stop] / 1e3])
    fmu = topic.strip("/")
    cols = []
    for name in groups[topic]:
        if name in master.input_names.get(fmu, []):
            cols.append(master.record_in[fmu][master.rows(start, stop), master.input_names[fmu].index(name)])
        else:
            cols.append(master.column(fmu, name, start, stop))
    return np.column_stack(cols)


def log_steps(recorder, master, groups: dict, start: int, stop: int, dt: float) -> None:
    """Hand steps [start, stop) of every logged signal group to the recorder, one block per topic."""
    if stop <= start:
        return
    t = np.arange(start, stop) * dt
    if getattr(master, "pacer", None) is not None:
        recorder.write_block("/master", t, group_block(master, {}, "/master", start, stop))
    for topic in groups:
        recorder.write_block(topic, t, group_block(master, groups, topic, start, stop))


def span_forces(run, span: int) -> tuple[np.ndarray, np.ndarray | None]:
    """The force in use over the span just closed and over the span before (None for the first)."""
    n, master = run.case.samples_per_span, run.master
    start = span * n
    force = master.column("catenary", "force_at_sample", start, start + n)
    previous = master.column("catenary", "force_at_sample", start - n, start) if span else None
    return force, previous


class McapObserver(RunObserver):
    """Logs every step to run.mcap a span at a time, the convergence record and the force of each
    span (/convergence, /span_force), and the steps of a span cut short when the run stops."""

    def __init__(self, recorder, groups: dict, dt_s: float):
        self.recorder = recorder
        self.groups = groups
        self.dt_s = dt_s
        self.logged_steps = 0

    def on_start(self, run) -> None:
        """Open run.mcap with the channels of the topology."""
        self.logged_steps = run.master.k  # a resumed run logs from its first new step on

    def _log_to(self, master, stop: int) -> None:
        log_steps(self.recorder, master, self.groups, self.logged_steps, stop, self.dt_s)
        self.logged_steps = max(self.logged_steps, stop)

    def on_span(self, run, span: int, record: dict) -> None:
        """Log the span's steps, its /convergence record and its /span_force."""
        self._log_to(run.master, run.master.k)
        t_s = run.master.k * self.dt_s
        self.recorder.write_event("/convergence", t_s, record)
        self.recorder.write_event("/span_force", t_s, span_force_record(span, self.dt_s, *span_forces(run, span)))
        self.recorder.flush()

    def on_end(self, run) -> None:
        """Log the steps of a span cut short and finish run.mcap."""
        try:
            if run.master is not None:
                self._log_to(run.master, run.master.k)
        finally:
            self.recorder.close()


class LiveObserver(RunObserver):
    """Serves the run's channels to Foxglove while it steps (orchestrator/live.py); with `wait`, the
    run steps once a viewer has subscribed (a stop request ends the wait)."""

    def __init__(self, endpoint: tuple[str, int], wait: bool = False):
        self.endpoint = endpoint
        self.wait = wait
        self.publisher = None

    def on_start(self, run) -> None:
        """Start the WebSocket server; with `wait`, wait until a viewer subscribes or a stop is asked."""
        from pantohil.models.case import CaseError

        from .live import LivePublisher

        master, groups, name = run.master, run.logged_groups, run.case.name
        try:
            self.publisher = LivePublisher(self.endpoint, groups, run.case.dt_s, lambda: max(master.k - 1, 0),
                                           lambda topic, start, stop: group_block(master, groups, topic, start, stop),
                                           name=f"pantohil {name} ({run.topology.name})")
        except Exception as exc:  # foxglove-sdk raises its own error types for a port in use or a bad host
            raise CaseError(f"--live: cannot serve on {self.endpoint[0]}:{self.endpoint[1]}: {exc}") from None
        # a step's records are final once the next step has started (the pacer writes a step's duration after it)
        print(f"live: Foxglove WebSocket server listening on {self.publisher.url} "
              f"(per-step channels every {self.publisher.decimation} steps)", flush=True)
        if self.wait:
            print("live: waiting for a viewer to subscribe (Ctrl-C to stop)", flush=True)
            self.publisher.wait_for_viewer(lambda: run.stop.requested)

    def on_span(self, run, span: int, record: dict) -> None:
        """Publish the span's /convergence and /span_force."""
        self.publisher.span_closed(run.master.k * run.case.dt_s, record, *span_forces(run, span))

    def on_end(self, run) -> None:
        """Stop the server and keep its summary for summary.json."""
        if self.publisher is not None:
            self.publisher.close()
            run.live = self.publisher.summary()


class CheckpointObserver(RunObserver):
    """Saves the run's state after every span (state/checkpoint.*), for `pantohil run --resume`."""

    def __init__(self, run_info: dict):
        self.run_info = run_info
        self.info = None

    def on_start(self, run) -> None:
        """Record the digests of the run's FMUs, which a checkpoint must match to be resumed."""
        from . import checkpoint

        self.info = {**self.run_info, "fmu_digests": checkpoint.fmu_digests(run.prepared.fmus)}

    def on_span(self, run, span: int, record: dict) -> None:
        """Save every FMU's state and the convergence record after the span (state/checkpoint.*)."""
        from . import checkpoint

        checkpoint.save(run.prepared.out_dir, run.master, run.monitor, span, self.info)
