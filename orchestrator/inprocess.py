"""The in-process engine (`pantohil run --engine inprocess`): the virtual HIL's three FMU classes
(fmus/pantohil_*.py) created in this process from the same parameter values and resource files as
their FMUs, and their models stepped in the fmpy master's Jacobi order (at step k every model gets the
outputs of step k-1: one step of latency per connection), without the FMI boundary.

Nothing of the physics is repeated here: initialisation is the FMU classes' own
(`exit_initialization_mode`), and a step calls the functions their `do_step` calls (the iteration's,
the rig's and the pantograph's `step`). What the FMUs compute only when a master reads an output
(the heights, the force in use and the dropper forces at the sample just received) is read from the
same state, step by step or, for what a span does not change again, once per span; the result is the
same to the bit as the FMU path's (tests/integration/test_inprocess.py).

The engine steps a span at a time (`run_steps`) and fills the master's records (the rings of
`RecordingMaster`) once per span, so that observers, logging and the summary see what they see with
the FMU master.
"""
from __future__ import annotations

import importlib
import math
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from pantohil.builder.build_fmus import CLASS_NAMES
from pantohil.builder.fmu_parameters import fmu_parameters
from pantohil.builder.staging import stage_case_data
from pantohil.builder.system import CONNECTIONS, FMU_NAMES
from pantohil.fmus.pantohil_catenary import SECOND_POINT_OUTPUTS
from pantohil.models.case import Case

from .master import RecordingMaster

CHUNK_STEPS = 1024  # compiled steps between two looks at a stop request (a span of most cases)

ENGINES = ("fmu", "inprocess")
_KINDS = {"Real": "Real", "Integer": "Integer", "Boolean": "Boolean", "String": "String"}


def _description(slave) -> SimpleNamespace:
    """The slave's variables as fmpy describes an FMU's (name, causality, type), in registration order."""
    variables = [SimpleNamespace(name=v.name, causality=v.causality.name if v.causality else "local",
                                 type=_KINDS[type(v).__name__]) for v in slave.vars.values()]
    return SimpleNamespace(modelVariables=variables)


def _read(slave, kind: str, names: list[str]) -> list:
    """Variables read as an FMI master reads them (pythonfmu's get_real / get_integer)."""
    by_name = {v.name: vr for vr, v in slave.vars.items()}
    return getattr(slave, f"get_{kind}")([by_name[n] for n in names])


def _set_parameters(slave, values: dict) -> None:
    """Parameters set before initialisation as an FMI master sets them (pythonfmu's setters)."""
    by_name = {v.name: v for v in slave.vars.values()}
    for name, value in values.items():
        if name not in by_name:
            raise ValueError(f"FMU {slave.instance_name} has no variable {name!r}")
        kind = type(by_name[name]).__name__
        by_name[name].setter({"Real": float, "Integer": int, "Boolean": bool, "String": str}[kind](value))


def create_slaves(case: Case, parameters: dict[str, dict]) -> dict:
    """The three FMU classes of the virtual HIL, initialised as their FMUs are in a master: from the
    case's parameter values and resource files (staged in a temporary folder), then `parameters`
    (by FMU: name -> value, what the master sets before initialising)."""
    delay = parameters.get("catenary", {}).get("delay_steps")
    values = fmu_parameters(case, delay)
    slaves = {}
    with tempfile.TemporaryDirectory(prefix="pantohil_inprocess_") as tmp:
        for name in FMU_NAMES:
            stage = Path(tmp) / name
            stage.mkdir()
            stage_case_data(name, values[name], case, stage, link=True)
            module = importlib.import_module(f"pantohil.fmus.pantohil_{name}")
            slave = getattr(module, CLASS_NAMES[name])(instance_name=name, resources=str(stage))
            slave.setup_experiment(0.0, None, None)
            _set_parameters(slave, parameters.get(name, {}))
            slave.enter_initialization_mode()
            slave.exit_initialization_mode()
            slaves[name] = slave
    return slaves


class InProcessMaster(RecordingMaster):
    """The virtual HIL's models stepped in this process with the Jacobi semantics of `JacobiMaster`,
    and its records (every real and integer output, every input, by step)."""

    steps_a_span_at_once = True  # `run_steps`

    def __init__(self, case: Case, connections, parameters: dict[str, dict], dt: float, capacity: int):
        if tuple(map(tuple, connections)) != CONNECTIONS:
            raise ValueError("the in-process engine steps the virtual HIL's own connections only")
        case.refuse_second_pantograph("the in-process engine")
        self.dt = dt
        self.names = list(FMU_NAMES)
        self.slaves = create_slaves(case, parameters)
        self._init_records({n: _description(s) for n, s in self.slaves.items()}, connections, capacity)
        self.values = {n: _read(s, "real", self.real_outputs[n]) for n, s in self.slaves.items()}
        self._constant_ints = {n: _read(s, "integer", self.int_outputs[n]) for n, s in self.slaves.items()}
        cat = self.slaves["catenary"]
        self._hil, self._z0 = cat.stepped_iteration, cat.static_heights_m
        self._rig, self._pan = self.slaves["rig"].stepped_rig, self.slaves["pantograph"].stepped_pantograph
        self._block_ns: list[float] = []  # wall time per step of each block
        from pantohil.models.hil.span_kernel import SpanKernel  # here: it imports the compiler, if there is one

        self._kernel = SpanKernel.of(self._hil, self._rig, self._pan)  # None: stepped in Python
        self._check_outputs()

    def _check_outputs(self) -> None:
        """Every output of the FMU classes has its column here (a new output must be added to `_columns`)."""
        columns = self._columns(0, [[0.0] * 7], np.zeros((1, 0)))
        for n in self.names:
            missing = [o for o in self.real_outputs[n] + self.int_outputs[n] if o not in columns[n]]
            if missing:
                raise ValueError(f"the in-process engine does not record {n}.{', '.join(missing)}")

    def run_steps(self, count: int, stop=None, force_limit: float = math.inf, height_limit: float = math.inf):
        """Up to `count` steps within the current span; stops before a step once `stop` is requested
        ("interrupted") and after a step whose force in use or command is beyond the limits (or NaN:
        "diverged"). Returns None, "interrupted" or "diverged"; the records cover every step taken."""
        if self._kernel is not None:
            return self._run_compiled(count, stop, force_limit, height_limit)
        hil, rig_step, pan_step = self._hil, self._rig.step, self._pan.step
        pan, fe, n = self._pan, self._hil.force_estimate, self._hil.n
        cat, rig, pant = self.values["catenary"], self.values["rig"], self.values["pantograph"]
        i_cmd, i_act, i_meas, i_f = self._value_index
        cmd, act, meas, f = cat[i_cmd], rig[i_act], rig[i_meas], pant[i_f]
        rows, outcome, t0 = [], None, time.perf_counter_ns()
        for _ in range(count):
            if stop is not None and stop.requested:
                outcome = "interrupted"
                break
            label = hil.k % n
            c = hil.step(meas)  # the catenary FMU's do_step
            a, m = rig_step(cmd, f)  # the rig FMU's
            f = pan_step(act)  # the pantograph FMU's
            cmd, act, meas = c, a, m
            used = fe[label]
            rows.append((c, hil.z[label], used, a, m, f, pan.head_height))
            if not (abs(used) <= force_limit and abs(c) <= height_limit):  # also catches NaN
                outcome = "diverged"
                break
        if rows:
            self._block_ns.append((time.perf_counter_ns() - t0) / len(rows))
            self._record(rows)
        return outcome

    def _run_compiled(self, count: int, stop, force_limit: float, height_limit: float):
        """`run_steps` through the compiled block (models/hil/span_kernel.py), `CHUNK_STEPS` at a time between
        looks at `stop`: the same steps and records to the bit."""
        i_cmd, i_act, i_meas, i_f = self._value_index
        inputs = np.array([self.values["catenary"][i_cmd], self.values["rig"][i_act], self.values["rig"][i_meas],
                           self.values["pantograph"][i_f]])
        limits, outcome, done = np.array([force_limit, height_limit], dtype=float), None, 0
        rows = np.empty((count, len(self._kernel.ROW_FIELDS)))
        t0 = time.perf_counter_ns()
        while done < count:
            if stop is not None and stop.requested:
                outcome = "interrupted"
                break
            taken, diverged = self._kernel.run(min(CHUNK_STEPS, count - done), inputs, limits, rows[done:])
            done += taken
            if diverged:
                outcome = "diverged"
                break
        if done:
            self._block_ns.append((time.perf_counter_ns() - t0) / done)
            self._record(rows[:done])
        return outcome

    @property
    def compiled_blocks(self) -> bool:
        """Whether the steps run as compiled blocks (models/hil/span_kernel.py) rather than model by model."""
        return self._kernel is not None

    @property
    def _value_index(self) -> tuple[int, int, int, int]:
        cat, rig, pan = (self.real_outputs[n] for n in self.names)
        return (cat.index("height_command"), rig.index("actuator_height"), rig.index("measured_force"),
                pan.index("contact_force"))

    def step(self) -> None:
        """One communication step of length dt (Jacobi), as `JacobiMaster.step`."""
        self.run_steps(1)

    def _corrections(self, k0: int, count: int) -> np.ndarray:
        """The dropper correction forces at each step's instant, [step, dropper]: a span visits each
        phase once, and the iteration keeps them by phase until the phase comes round again."""
        hil = self._hil
        if not getattr(hil, "nd", 0):
            return np.zeros((count, 0))
        return hil.correction_at[np.arange(k0, k0 + count) % hil.n].copy()

    def _columns(self, k0: int, rows: list, corrections: np.ndarray) -> dict[str, dict]:
        """Every output of steps k0.. by FMU and name, from the rows the steps kept (see `run_steps`)."""
        block = np.asarray(rows, dtype=float)
        count = len(block)
        labels = np.arange(k0, k0 + count) % self._hil.n
        cat = {"height_command": block[:, 0], "height_at_sample": block[:, 1], "force_at_sample": block[:, 2],
               "profile_at_sample": self._z0[labels], "sample_index": labels,
               "span_index": np.arange(k0, k0 + count) // self._hil.n,
               "slack_droppers": np.count_nonzero(corrections, axis=1),
               **{name: np.zeros(count) for name in SECOND_POINT_OUTPUTS}}  # one contact point (refused: two)
        for d in range(len([o for o in self.real_outputs["catenary"] if o.startswith("dropper_correction_")])):
            cat[f"dropper_correction_{d + 1}"] = corrections[:, d] if d < corrections.shape[1] else np.zeros(count)
        columns = {"catenary": cat, "rig": {"actuator_height": block[:, 3], "measured_force": block[:, 4]},
                   "pantograph": {"contact_force": block[:, 5], "head_height": block[:, 6]}}
        for n in self.names:  # integer outputs the models keep constant after initialisation
            for name, value in zip(self.int_outputs[n], self._constant_ints[n], strict=True):
                columns[n].setdefault(name, np.full(count, value))
        return columns

    def _record(self, rows: list) -> None:
        """Put the block's outputs and inputs into the rings and make its last outputs the current values."""
        k0, count = self.k, len(rows)
        columns = self._columns(k0, rows, self._corrections(k0, count))
        ring = self.rows(k0, k0 + count)
        previous = dict(self.values)  # the lists are replaced below, not changed
        for n in self.names:
            out = np.column_stack([columns[n][o] for o in self.real_outputs[n]])
            self.record[n][ring] = out
            if n in self.record_int:
                self.record_int[n][ring] = np.column_stack([columns[n][o] for o in self.int_outputs[n]])
            self.values[n] = out[-1].tolist()
            columns[n]["_block"] = out
        for n, wiring in self._in_map.items():  # an input at step k is its source's output of step k-1
            self.record_in[n][ring] = np.column_stack([
                np.concatenate([[previous[src][j]], columns[src]["_block"][:-1, j]])
                for src, j in wiring])
        self.k = k0 + count

    def per_step_us(self) -> dict[str, float]:
        """Median wall time per step of the three models together over the blocks stepped [us]."""
        return {"inprocess": float(np.median(self._block_ns)) / 1000.0} if self._block_ns else {}

    def close(self) -> None:
        """Nothing to release: the models are plain objects."""
        self.slaves = {}

