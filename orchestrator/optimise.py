"""`pantohil optimise CATENARY_FILE --case CASE --vary heights|spacing`: the catenary design of least contact-force
standard deviation (0-20 Hz, EN 50367's quality indicator) over the contact-wire heights at the droppers or the
dropper positions, the span kept symmetric, every dropper in tension and within the designer's limits (Paper D sec.
5.3 after its reference [16]). Each design is evaluated by its PFEM steady state with the case's pantograph taken as
linear and its droppers slackening (models/catenary/pfem/design_evaluation.py: one operator build and an active-set
solve per speed), on Dask; by default the max may not rise above the nominal design's nor the min fall below it
(Paper D Table 2's pattern). The nominal and the optimised design are then run through the virtual HIL with dropper
slackening (the confirmation). The folder holds the journal of every design (resumable: the same command continues a
folder it started), and at the end the optimised catenary file, a case for it, the history and the report.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from pantohil.models.case import apply_overrides, load_case, load_case_dict
from pantohil.models.catenary.design import DesignLimits, check_symmetric, design_space
from pantohil.models.catenary.fe.definition import CatenaryError, build_definition
from pantohil.models.catenary.fe.model import form_find
from pantohil.models.catenary.pfem.design_evaluation import SpeedPoint
from pantohil.models.catenary.pfem.steady_state import span_frequencies_rad_s
from pantohil.models.errors import InputError
from pantohil.models.input_files import load_toml
from pantohil.models.pantograph.interface import receptance

from .output_paths import check_output_folder
from .report import write_json_atomic

MARKER = "optimise.json"
EVALUATION = "PFEM steady state with dropper slackening, 0-20 Hz"  # in the marker: a folder of another kind is refused
EXTREMES = ("nominal", "free")  # the max and min bounded by the nominal design's, or not
STEP = {"heights": 1e-3, "spacing": 0.05}  # finite-difference step of each design kind [m]
FILE_KEYS = (("rig", "file"), ("link", "key_file"), ("profile", "catenary_file"), ("profile", "csv_file"))


@dataclass(frozen=True)
class OptimiseRequest:
    """What `pantohil optimise` was asked: the catenary, the case (pantograph, step, PFEM settings), the
    variables, the speeds and their weights, the limits, and the search's budget."""

    catenary_file: Path
    case_path: Path | None
    overrides: tuple[str, ...] = ()
    vary: str = "heights"
    speeds_kmh: tuple[float, ...] = ()  # empty: the case's speed
    weights: tuple[float, ...] = ()  # empty: equal
    limits: DesignLimits = field(default_factory=DesignLimits)
    max_designs: int = 200
    explore: int = 24  # designs of the first, parallel sample of the bounds
    starts: int = 1  # descents: from the best designs evaluated by then
    extremes: str = "nominal"
    max_minutes: float = 13.5  # the search's time; the confirmation (under a minute) comes after it

    def identity(self) -> dict:
        """What makes two requests the same optimisation (the marker of the folder)."""
        return {"catenary_file": str(Path(self.catenary_file).resolve()),
                "catenary_sha": _sha(Path(self.catenary_file)),
                "case": str(Path(self.case_path).resolve()) if self.case_path else None,
                "overrides": list(self.overrides), "vary": self.vary, "speeds_kmh": list(self.speeds_kmh),
                "weights": list(self.weights), "limits": asdict(self.limits), "explore": self.explore,
                "starts": self.starts, "extremes": self.extremes, "evaluation": EVALUATION}


def _sha(path: Path) -> str:
    import hashlib

    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


@dataclass
class Problem:
    """The checked optimisation: the nominal design, its variables and bounds, and the speeds."""

    raw: dict
    cat: object
    space: object
    x0: np.ndarray
    bounds: list
    points: list[SpeedPoint]


def case_overrides(request: OptimiseRequest, speed_kmh: float | None, catenary_file: Path) -> list[str]:
    """The case's overrides with the catenary file as its PFEM catenary and the speed. The operators keep the
    case's own f_max and the force is filtered afterwards, as `pantohil run` and `pantohil fem-sim` do (cutting
    the operators at 20 Hz is not filtering the force: the periodic catenary couples harmonics)."""
    speed = [] if speed_kmh is None else [f"run.speed_kmh={speed_kmh:g}"]
    return [*request.overrides, "catenary.model=pfem", f"catenary.definition_file={Path(catenary_file).resolve()}",
            *speed]


def speed_points(request: OptimiseRequest) -> list[SpeedPoint]:
    """At every speed asked (the case's own if none): the case's operator settings, pantograph receptance at the
    span's harmonics and EN 50367 mean force."""
    speeds = request.speeds_kmh or (None,)
    weights = request.weights or (1.0,) * len(speeds)
    if len(weights) != len(speeds):
        raise InputError(f"--weights: {len(weights)} weights for {len(speeds)} speeds", key="--weights")
    points = []
    for speed, weight in zip(speeds, weights, strict=True):
        case = load_case(request.case_path, case_overrides(request, speed, request.catenary_file))
        w = span_frequencies_rad_s(case.samples_per_span, case.dt_s, case.n_harmonics)
        points.append(SpeedPoint(case.speed_kmh, case.pfem_settings(), receptance(case.pantograph, w),
                                 case.pantograph.uplift_force_N, float(weight)))
    return points


def prepare(request: OptimiseRequest) -> Problem:
    """Every input checked before anything is written: one InputError (exit 2) naming what is wrong."""
    space = design_space(request.vary)
    if not request.max_minutes > 0:
        raise InputError(f"--max-minutes: must be > 0 (got {request.max_minutes:g})", key="--max-minutes")
    if request.max_designs < 2:
        raise InputError(f"--max-designs: at least 2 (got {request.max_designs})", key="--max-designs")
    if request.extremes not in EXTREMES:
        raise InputError(f"--extremes: {request.extremes!r} is not one of {', '.join(EXTREMES)}", key="--extremes")
    if request.starts < 1 or request.explore < 0:
        raise InputError("--starts: at least 1 descent, and --explore at least 0 designs", key="--starts")
    try:
        raw = load_toml(Path(request.catenary_file), "catenary file")
        cat = build_definition(raw, Path(request.catenary_file))
        nominal = form_find(cat, 3)
    except CatenaryError as exc:
        raise InputError(f"{request.catenary_file}: {exc}", key=exc.key) from None
    check_symmetric(cat)
    shortest = float(nominal.dropper_lengths_m.min())
    if shortest < request.limits.min_dropper_length_m:
        raise InputError(f"--min-dropper-length: the nominal design's shortest dropper is {shortest:.3f} m, below "
                         f"{request.limits.min_dropper_length_m:g} m: no design within the limits to start from",
                         key="--min-dropper-length")
    if any(w <= 0 for w in request.weights):
        raise InputError("--weights: every weight must be positive", key="--weights")
    return Problem(raw, cat, space, space.start(cat), space.bounds(cat, request.limits), speed_points(request))


def open_folder(out: Path, request: OptimiseRequest, overwrite: bool) -> None:
    """The output folder: new, or one this same optimisation started (it continues); another optimisation's
    folder is refused in one line."""
    marker = Path(out) / MARKER
    if marker.exists() and not overwrite:
        try:
            previous = json.loads(marker.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError):
            previous = None
        if previous != request.identity():
            raise InputError(f"--out {out}: holds another optimisation ({MARKER} differs); use a new folder or "
                             "--overwrite", key="--out")
        return
    check_output_folder(Path(out), "--out", overwrite)
    if overwrite and Path(out).exists():
        import shutil

        shutil.rmtree(out)
    Path(out).mkdir(parents=True, exist_ok=True)
    write_json_atomic(marker, request.identity())


def written_case(request: OptimiseRequest, problem: Problem, catenary_name: str) -> dict:
    """The case for the optimised catenary (its TOML as a dict): the input case with its overrides, the PFEM
    catenary beside it, the first speed, the case's own f_max, and every file it names by an absolute path."""
    raw, source = load_case_dict(request.case_path)
    raw = apply_overrides(raw, case_overrides(request, problem.points[0].speed_kmh, Path(catenary_name)))
    raw["catenary"]["definition_file"] = catenary_name
    for section, key in FILE_KEYS:
        value = raw.get(section, {}).get(key)
        if value:
            raw[section][key] = str((source.parent / value).resolve())
    head = raw.setdefault("case", {})
    head["name"] = f"{head.get('name', 'case')}_{request.vary}_optimised"
    head["description"] = (f"{head.get('description', '')} | catenary optimised over the {request.vary} by pantohil "
                           f"optimise at {', '.join(f'{p.speed_kmh:g}' for p in problem.points)} km/h")
    return raw
