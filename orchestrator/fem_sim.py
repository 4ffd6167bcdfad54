"""`pantohil fem-sim`: the conventional finite-section simulation of a case (Paper C sec. 6) and its
run folder; `pantohil compare`: two runs overlaid."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pantohil.models.case import Case, CaseError
from pantohil.models.catenary.fe.definition import load_definition
from pantohil.models.metrics import LOWPASS_CUTOFF_HZ, force_statistics, lowpass, lowpass_periodic

from . import report
from .output_paths import atomic_output_folder, check_output_folder
from .recorder import McapWriter
from .run_folder import CENTRAL_SPANS, STEADY_SPAN, read_summary, read_table

CUTOFF_HZ = LOWPASS_CUTOFF_HZ


def central_spans(n_spans: int, central: int) -> list[int]:
    """Indices of the `central` spans in the middle of an n-span section, with 2 spans on each side."""
    if n_spans < 1:
        raise CaseError(f"spans: must be at least 1 (got {n_spans})")
    if central < 1:
        raise CaseError(f"central spans: must be at least 1 (got {central})")
    if n_spans < central + 4:
        raise CaseError(f"spans: {n_spans} spans leave no central region of {central} spans with 2 spans on "
                        f"each side (need at least {central + 4})")
    first = (n_spans - central) // 2
    return list(range(first, first + central))


def run_fem_sim(case: Case, n_spans: int, out_dir: Path, central: int = 3, progress: bool = True,
                overwrite: bool = False) -> dict:
    """`pantohil fem-sim`: simulate an n-span section of a case's catenary and write its run folder.

    summary.json holds the statistics of the central spans after the 20 Hz low-pass; central_spans.csv
    the force on the PFEM run's grid; also dropper corrections, run.mcap and plots. With a
    [second_pantograph], both pantographs cross the section L apart (the second's force in f2_N, in
    summary.json's second_pantograph and in run.mcap's /pantograph_2), each over the same central spans.
    The folder is checked before the simulation (new or empty; `overwrite` replaces it whole) and appears
    complete or not at all.
    """
    spans = central_spans(n_spans, central)
    if not case.sections.catenary.definition_file:
        raise CaseError("catenary.definition_file: the case's catenary has no catenary file to build a section from")
    path = (case.source.parent / case.sections.catenary.definition_file).resolve()
    cat = load_definition(path)
    _check_second_pantograph(case, n_spans, cat.span_m)
    from pantohil.models.catenary.fe.simulation import FE_PANTOGRAPHS

    if case.pantograph.model not in FE_PANTOGRAPHS:
        raise CaseError(f"pantograph.model: fem-sim steps the pantograph models {', '.join(FE_PANTOGRAPHS)} "
                        f"(a pantograph in contact), not {case.pantograph.model!r}")
    with atomic_output_folder(out_dir, "--out", overwrite) as part:
        res = _simulate(case, cat, n_spans, progress)
        summary = _write_section(part, case, cat, path, n_spans, spans, res)
    return summary


def _simulate(case: Case, cat, n_spans: int, progress: bool):
    """The conventional simulation of the section, with its progress (a bar, or lines in a log)."""
    from pantohil.models.catenary.fe.simulation import simulate_section
    from pantohil.models.progress import progress as progress_bar

    with progress_bar(1, f"fem-sim {n_spans} spans", "step", progress) as bar:
        def tick(k, total):
            bar.total = total
            bar.n = k
            bar.refresh()

        second = case.sections.second_pantograph
        if second is None:
            return simulate_section(cat, case.pantograph, n_spans, case.speed_m_s, case.dt_s,
                                    case.sections.pfem.droppers, progress=tick,
                                    reference_height_m=case.reference_height_m())
        from pantohil.models.catenary.asm.pair import second_offset_m
        from pantohil.models.catenary.fe.simulation import simulate_points
        from pantohil.models.hil.pair_loop import pair_reference_heights_m

        return simulate_points(cat, case.pantograph, n_spans, case.speed_m_s, case.dt_s,
                               (0.0, second_offset_m(second.spacing_m, second.position)),
                               pair_reference_heights_m(case), case.sections.pfem.droppers, progress=tick)


def _check_second_pantograph(case: Case, n_spans: int, span_m: float) -> None:
    """A second pantograph must be on the section with the first: its spacing shorter than the section."""
    second = case.sections.second_pantograph
    if second is not None and second.spacing_m >= n_spans * span_m:
        raise CaseError(f"second_pantograph.spacing_m: {second.spacing_m:g} m is not shorter than the {n_spans}-span "
                        f"section ({n_spans * span_m:g} m): the two pantographs would never be on it together",
                        key="second_pantograph.spacing_m")


def passages(res) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """Each pantograph's passage over the section, (its first result row, its force, its position), as many rows
    as the section's steps: the first's row k is where a single pantograph's is (sample m of span j at row
    j N + m - 1 of the passage), the second's at its own positions."""
    if res.forces_N is None:
        return [(0, res.force_N, res.x_m)]
    n_steps = len(res.force_N) - max(res.entry_steps)
    return [(e, res.forces_N[e:e + n_steps, i], res.positions_m[e:e + n_steps, i])
            for i, e in enumerate(res.entry_steps)]


def _write_section(out_dir: Path, case: Case, cat, path: Path, n_spans: int, spans: list[int], res) -> dict:
    """The run folder of a simulated section: tables, run.mcap, plots, and summary.json last."""
    n, dt, slacken = case.samples_per_span, case.dt_s, case.sections.pfem.droppers
    # sample m of span j is the instant t = (j n + m) dt of a passage; its row k is at t = (k + 1) dt
    sel = np.concatenate([np.arange(j * n - 1, (j + 1) * n - 1) for j in spans])
    tracks = [_Passage(e, f, x, lowpass(f, dt), spans, n) for e, f, x in passages(res)]
    first = tracks[0]
    per_span = len(cat.dropper_positions_m)
    mid = spans[len(spans) // 2]
    d_mid = slice(mid * per_span, (mid + 1) * per_span)
    corr_mid = res.dropper_correction_N[first.entry + mid * n - 1:first.entry + (mid + 1) * n - 1, d_mid]
    central_supports = list(range(spans[0], spans[-1] + 2))
    rows = np.concatenate([t.entry + sel for t in tracks])  # every pantograph's central samples
    summary = {
        "case": case.name, "model": "conventional FE section (HHT, penalty contact, dropper slackening)",
        "catenary_file": str(path), "catenary_label": _label(cat), "n_spans": n_spans, "central_spans": spans,
        "speed_kmh": case.speed_kmh, "dt_s": dt, "samples_per_span": n, "droppers_slacken": slacken,
        "contact_force": _force_summary(first.force, first.filtered, sel),
        "max_support_uplift_m": float(np.max(res.support_uplift_m[rows][:, central_supports])),
        "droppers": {"slack_steps": [int(c) for c in np.count_nonzero(corr_mid > 0, axis=0)],
                     "max_correction_N": [float(c) for c in corr_mid.max(axis=0)]},
        "timing": {"wall_s": res.wall_s, "steps": len(res.force_N), "peak_memory_MB": res.peak_memory_bytes / 1e6},
        "en50318": "not claimed: the standard's reference model and acceptance ranges were not available",
    }
    if len(tracks) > 1:
        summary["sample_offset_m"] = first.sample_offset_m(case.speed_m_s * dt)
        summary["second_pantograph"] = _second_summary(case, tracks[1], sel)
    _write_force_tables(out_dir, spans, tracks, dt, n, corr_mid, per_span)
    _write_mcap(out_dir, case, n_spans, dt, per_span, res, tracks, d_mid)
    _write_plots(out_dir, case, n_spans, dt, cat, tracks, spans, corr_mid, mid)
    report.write_json_atomic(out_dir / "summary.json", summary)
    return summary


@dataclass
class _Passage:
    """A pantograph's passage over the section: its first result row, force, position and 20 Hz low-pass over
    the passage, and its central spans' raw and low-passed force (span, sample)."""
    entry: int
    force: np.ndarray
    x: np.ndarray
    filtered: np.ndarray
    spans: list[int]
    n: int

    def sample_offset_m(self, step_m: float) -> float:
        """How far past j L + m v dt its sample m of span j lies: 0 for the pantograph in front, up to one step's
        travel for the one behind (the spacing is kept exactly, the steps are the front one's)."""
        return round(float(self.x[0] - step_m), 12)

    @property
    def blocks_raw(self) -> np.ndarray:
        """The raw force of the central spans, [span, sample]."""
        return np.stack([self.force[j * self.n - 1:(j + 1) * self.n - 1] for j in self.spans])

    @property
    def blocks(self) -> np.ndarray:
        """The 20 Hz low-passed force of the central spans, [span, sample]."""
        return np.stack([self.filtered[j * self.n - 1:(j + 1) * self.n - 1] for j in self.spans])


def _force_summary(force: np.ndarray, filtered: np.ndarray, sel: np.ndarray) -> dict:
    """A pantograph's contact-force statistics over its central samples `sel`: 20 Hz low-passed (EN 50367), its
    contact loss and the raw force's."""
    return {**force_statistics(filtered[sel]), "filter": f"zero-phase {CUTOFF_HZ:g} Hz low-pass",
            "contact_loss_pct": float(100 * np.mean(force[sel] <= 0.0)), "raw": force_statistics(force[sel])}


def _second_summary(case: Case, track: _Passage, sel: np.ndarray) -> dict:
    """summary.json's second_pantograph: spacing, position, model, its force statistics over the same central
    spans (which it crosses L / v later or earlier), and where its samples lie."""
    second = case.sections.second_pantograph
    p = case.pantograph
    return {"spacing_m": second.spacing_m, "position": second.position,
            "pantograph": {"model": p.model, "masses_kg": list(p.masses_kg),
                           "stiffnesses_N_m": list(p.stiffnesses_N_m), "dampings_Ns_m": list(p.dampings_Ns_m),
                           "contact_stiffness_N_m": p.contact_stiffness_N_m, "uplift_force_N": p.uplift_force_N,
                           "same_as_first": True},
            "contact_force": _force_summary(track.force, track.filtered, sel),
            "entry_s": track.entry * case.dt_s, "sample_offset_m": track.sample_offset_m(case.speed_m_s * case.dt_s)}


def _write_force_tables(out_dir: Path, spans, tracks: list[_Passage], dt, n, corr_mid, per_span) -> None:
    """Write central_spans.csv (raw and low-passed force of the central spans, each pantograph's) and
    dropper_corrections.csv."""
    cut = f"{CUTOFF_HZ:g}"
    header = f"span,t_s,f_N,f_lowpass_{cut}hz_N" + (f",f2_N,f2_lowpass_{cut}hz_N" if len(tracks) > 1 else "")
    columns = [b for t in tracks for b in (t.blocks_raw, t.blocks)]
    with open(out_dir / "central_spans.csv", "w") as fh:
        fh.write(header + "\n")  # the low-pass is of each whole passage (no edge effect)
        for s, j in enumerate(spans):
            for m in range(n):
                fh.write(f"{j},{m * dt:.6f}," + ",".join(f"{c[s, m]:.9g}" for c in columns) + "\n")
    np.savetxt(out_dir / "dropper_corrections.csv", np.column_stack([np.arange(n) * dt, corr_mid]), delimiter=",",
               header="t_s," + ",".join(f"dropper_{d + 1}_N" for d in range(per_span)), comments="", fmt="%.9g")


def _write_mcap(out_dir: Path, case: Case, n_spans: int, dt, per_span, res, tracks: list[_Passage], d_mid) -> None:
    """Write run.mcap: each pantograph's position and force over its passage (/pantograph, /pantograph_2) and the
    middle central span's dropper forces."""
    channel = {"x_m": "pantograph position [m]", "contact_force": "contact force [N]",
               "filtered_force": f"{CUTOFF_HZ:g} Hz low-pass [N]"}
    topics = ["/pantograph"] + [f"/pantograph_{i + 1}" for i in range(1, len(tracks))]
    recorder = McapWriter(out_dir / "run.mcap", {
        **{topic: channel for topic in topics},
        "/droppers": {f"dropper_{d + 1}": f"force of dropper {d + 1} of the middle central span [N]"
                      for d in range(per_span)}}, {"case": case.name, "n_spans": n_spans, "dt_s": dt})
    try:
        for topic, t in zip(topics, tracks, strict=True):
            recorder.write_block(topic, res.t_s[t.entry:t.entry + len(t.force)],
                                 np.column_stack([t.x, t.force, t.filtered]))
        recorder.write_block("/droppers", res.t_s, res.dropper_force_N[:, d_mid].astype(float))
    finally:
        recorder.close()


def _write_plots(out_dir: Path, case: Case, n_spans: int, dt, cat, tracks: list[_Passage], spans, corr_mid,
                 mid) -> None:
    """Plot the force along the section (each pantograph's), the central spans overlaid and the dropper
    corrections."""
    first = tracks[0]
    second = None if len(tracks) == 1 else (tracks[1].x, tracks[1].force, tracks[1].filtered)
    report.plot_section_force(out_dir / "force_along_section.png", first.x, first.force, first.filtered, cat.span_m,
                              spans, f"{case.title}: {n_spans}-span section, {case.speed_kmh:.0f} km/h", second)
    overlay = {f"span {j} ({CUTOFF_HZ:g} Hz)": blk for j, blk in zip(spans, first.blocks, strict=False)}
    for t in tracks[1:]:
        overlay.update({f"pantograph 2, span {j} ({CUTOFF_HZ:g} Hz)": blk
                        for j, blk in zip(spans, t.blocks, strict=False)})
    report.plot_force_comparison(out_dir / "central_spans.png", dt, overlay, f"{case.title}: central spans overlaid")
    report.plot_dropper_corrections(out_dir / "dropper_corrections.png", dt, corr_mid,
                                    f"{case.title}: dropper correction forces, span {mid}")


def _label(cat) -> str:
    text = f"{cat.name} {cat.values.get('catenary', {}).get('description', '')}"
    return "benchmark-like (reconstructed)" if "benchmark" in text else cat.name


def _summary_dt(s: dict, run: Path) -> float:
    """A run summary's step dt_s, a finite number > 0 (CaseError naming the folder otherwise)."""
    dt = s.get("dt_s")
    if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not 0 < dt < 1e3:
        raise CaseError(f"run summary {run / 'summary.json'}: dt_s must be a positive number of seconds "
                        f"(got {dt!r})")
    return float(dt)


def _force_table(run: Path, name: str, columns: int) -> np.ndarray:
    """A run folder's force table with at least `columns` columns, two rows and finite numbers."""
    d = read_table(run, name)
    if d.shape[1] < columns or d.shape[0] < 2 or not np.all(np.isfinite(d)):
        raise CaseError(f"run table {run / name}: expected at least 2 rows of {columns} finite numbers "
                        f"(got {d.shape[0]} x {d.shape[1]})")
    return d


def span_force(run: Path, point: int = 0) -> tuple[np.ndarray, float, str]:
    """One span of contact force of a run folder, 20 Hz low-passed: the converged span of a HIL run or
    the mean of the central spans of a fem-sim run; `point` 1: the second pantograph's, in the order of its
    own positions (a HIL run records it when the first is at x_n; it is then at x_n + offset)."""
    run = Path(run)
    s = read_summary(run)
    dt = _summary_dt(s, run)
    if point and not isinstance(s.get("second_pantograph"), dict):
        raise CaseError(f"{run}: the run has no second pantograph")
    if (run / CENTRAL_SPANS).exists():
        d = _force_table(run, CENTRAL_SPANS, 6 if point else 4)
        spans = [int(j) for j in np.unique(d[:, 0])]
        blocks = [d[d[:, 0] == j, 5 if point else 3] for j in spans]
        if len({len(b) for b in blocks}) != 1:
            raise CaseError(f"run table {run / CENTRAL_SPANS}: its spans hold different numbers of samples")
        return np.stack(blocks).mean(axis=0), dt, f"fem-sim {s.get('n_spans')} spans (mean of spans {spans})"
    if (run / STEADY_SPAN).exists():
        d = _force_table(run, STEADY_SPAN, 7 if point else 4)
        model = s.get("catenary", {}).get("model") if isinstance(s.get("catenary"), dict) else None
        force = lowpass_periodic(d[:, 6 if point else 3], dt, CUTOFF_HZ)
        if point:
            force = np.roll(force, _second_shift(s, len(force), dt, run))
        return force, dt, f"HIL {model} ({s.get('case')})"
    raise CaseError(f"{run}: neither steady_span.csv nor central_spans.csv")


def _second_shift(s: dict, n: int, dt: float, run: Path) -> int:
    """The samples s with the second pantograph at x_n + offset = x_(n+s) (mod span): a whole number, else a
    CaseError (its force is then on another grid than a section's)."""
    from pantohil.models.catenary.asm.pair import second_offset_m

    second = s["second_pantograph"]
    try:
        step = float(s["speed_kmh"]) / 3.6 * dt
        shift = second_offset_m(float(second["spacing_m"]), second["position"]) / step
    except (KeyError, TypeError, ValueError):
        raise CaseError(f"{run / 'summary.json'}: its second_pantograph has no spacing and position") from None
    if abs(shift - round(shift)) > 1e-6:
        raise CaseError(f"{run}: the second pantograph is not a whole number of samples from the first")
    return int(round(shift)) % n


def correction_measures(corrections: np.ndarray, dt_s: float) -> dict:
    """Per dropper (columns), its correction forces over one span (rows, Paper C eqs. 36-40): the largest
    value, the steps it acts on and its impulse, the sum of correction x dt [N s].

    A slack interval lasts a few steps, so its largest value depends on the time grid and on the instant
    within the step a model applies it (the PFEM: one instant per dropper per step, its elongation
    reduced to N_hd harmonics, Paper D sec. 3.7; fem-sim: exact at every step). The impulse, the
    momentum the correction takes from the wire, is what both models must agree on."""
    c = np.asarray(corrections, dtype=float)
    return {"correction_max_N": c.max(axis=0).tolist(),
            "slack_steps": np.count_nonzero(c > 0, axis=0).tolist(),
            "correction_impulse_Ns": (c.sum(axis=0) * dt_s).tolist()}


def _percent_of(value: float, std_ref: float, reference: np.ndarray) -> float | None:
    """value in % of the reference's std; None where that std is round-off of a constant force (no variation
    to compare with: 1e-9 of its mean level, or of 1 N)."""
    if std_ref <= 1e-9 * max(1.0, float(np.max(np.abs(reference)))):
        return None
    return 100 * value / std_ref


def _dropper_tables(a: Path, b: Path) -> tuple[np.ndarray, np.ndarray] | None:
    """Both runs' dropper correction tables, where both have one of the same shape."""
    name = "dropper_corrections.csv"
    if not ((a / name).exists() and (b / name).exists()):
        return None
    da, db = _force_table(a, name, 2), _force_table(b, name, 2)
    return (da, db) if da.shape == db.shape else None


def compare_runs(a: Path, b: Path, out_dir: Path, overwrite: bool = False) -> dict:
    """`pantohil compare`: the 20 Hz contact force of two run folders, their stds and RMS difference; the
    folder out_dir appears complete or not at all (`overwrite` replaces a used one)."""
    check_output_folder(out_dir, "--out", overwrite)  # before reading the runs
    fa, dta, la = span_force(a)
    fb, dtb, lb = span_force(b)
    if la == lb:  # two runs of one case: their folders tell them apart
        la, lb = f"{la}, {Path(a).name}", f"{lb}, {Path(b).name}"
        if la == lb:
            la, lb = f"{la} (first)", f"{lb} (second)"
    if len(fa) != len(fb) or abs(dta - dtb) > 1e-12:
        raise CaseError(f"compare: the runs are on different grids ({len(fa)} samples of {dta:g} s, "
                        f"{len(fb)} of {dtb:g} s)")
    diff = fa - fb
    std_ref = float(np.std(fb))
    rms = float(np.sqrt(np.mean(diff ** 2)))
    res = {"a": {"run": str(a), "label": la, **force_statistics(fa)},
           "b": {"run": str(b), "label": lb, **force_statistics(fb)},
           "std_difference_pct": _percent_of(float(np.std(fa)) - std_ref, std_ref, fb),
           "rms_difference_N": rms,
           "rms_difference_pct_of_std_b": _percent_of(rms, std_ref, fb),
           "filter": f"zero-phase {CUTOFF_HZ:g} Hz low-pass"}
    second = _second_comparison(Path(a), Path(b))
    if second is not None:
        res["second_pantograph"] = second
    droppers = _dropper_tables(Path(a), Path(b))  # every input read before anything is written
    with atomic_output_folder(out_dir, "--out", overwrite) as part:
        _write_comparison(part, res, (fa, dta, la), (fb, dtb, lb), droppers)
    return res


def _second_comparison(a: Path, b: Path) -> dict | None:
    """Both runs' second pantographs compared as the first (std difference, RMS difference in % of b's std),
    where both have one."""
    if not all(isinstance(read_summary(r).get("second_pantograph"), dict) for r in (a, b)):
        return None
    fa, _, _ = span_force(a, 1)
    fb, _, _ = span_force(b, 1)
    std_ref = float(np.std(fb))
    rms = float(np.sqrt(np.mean((fa - fb) ** 2)))
    return {"a": force_statistics(fa), "b": force_statistics(fb),
            "std_difference_pct": _percent_of(float(np.std(fa)) - std_ref, std_ref, fb), "rms_difference_N": rms,
            "rms_difference_pct_of_std_b": _percent_of(rms, std_ref, fb)}


def _write_comparison(out_dir: Path, res: dict, run_a: tuple, run_b: tuple, droppers) -> None:
    """compare.json (last) and the plots of `pantohil compare`; the dropper measures go into res."""
    (fa, dta, la), (fb, dtb, lb) = run_a, run_b
    report.plot_force_comparison(out_dir / "contact_force.png", dta, {la: fa, lb: fb},
                                 f"contact force, {CUTOFF_HZ:g} Hz: std {np.std(fa):.2f} vs {np.std(fb):.2f} N, "
                                 f"rms difference {res['rms_difference_N']:.2f} N")
    if droppers is not None:
        da, db = droppers
        ma, mb = correction_measures(da[:, 1:], dta), correction_measures(db[:, 1:], dtb)
        for key in ma:
            res[f"dropper_{key}"] = {"a": ma[key], "b": mb[key]}
        report.plot_dropper_comparison(out_dir / "dropper_corrections.png", da, db, la, lb)
    report.write_json_atomic(out_dir / "compare.json", res)
