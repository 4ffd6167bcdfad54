"""Run the pantohil HIL system of this package in fmpy and compare it with the reference results.

A fixed-step Jacobi master (the semantics of libcosim): at every step each FMU gets the outputs of
the previous step. Needs only what requirements.txt lists; pantohil itself is not needed.

    python run_fmpy.py            # runs, writes steady_span.csv, compares with reference/
"""
import json
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.ssp.ssd import read_ssd

HERE = Path(__file__).resolve().parent


def _parameter_values(ssd) -> dict:
    """The SSD's parameter bindings as {component: {variable: text value}}."""
    values = {}
    for binding in ssd.system.parameterBindings:
        for pset in binding.parameterValues:
            for p in pset.parameters:
                comp, var = p.name.split(".", 1)
                values.setdefault(comp, {})[var] = p.value
    return values


def _instantiate_fmus(ssd, work: Path, values: dict) -> dict:
    """Unzip, instantiate, parameterise and initialise every FMU of the system: {name: (fmu, variables)}."""
    fmus, md = {}, {}
    for comp in ssd.system.elements:
        path = work / "ssp" / comp.source
        unzipped = work / comp.name
        with zipfile.ZipFile(path) as z:
            z.extractall(unzipped)
        md[comp.name] = read_model_description(str(path))
        vr = {v.name: v for v in md[comp.name].modelVariables}
        fmu = FMU2Slave(guid=md[comp.name].guid, unzipDirectory=str(unzipped),
                        modelIdentifier=md[comp.name].coSimulation.modelIdentifier, instanceName=comp.name)
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        for var, text in values.get(comp.name, {}).items():
            v = vr[var]  # fmpy reads SSV values as text: convert by the variable's type
            value = {"Real": float, "Integer": int}.get(v.type, lambda x: str(x).lower() == "true")(text)
            getattr(fmu, f"set{v.type}")([v.valueReference], [value])
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmus[comp.name] = (fmu, vr)
    return fmus


def _co_simulate(ssd, fmus: dict, cfg: dict) -> np.ndarray:
    """Run the fixed-step Jacobi master and return the rig's measured force over the last span."""
    wires = [(c.startElement, c.startConnector, c.endElement, c.endConnector) for c in ssd.system.connections]
    outputs = {}
    for name, (fmu, vr) in fmus.items():
        outputs[name] = {c[1]: fmu.getReal([vr[c[1]].valueReference])[0] for c in wires if c[0] == name}
    dt, steps, n = cfg["dt_s"], cfg["steps"], cfg["samples_per_span"]
    force = np.zeros(n)
    for k in range(steps):
        for src, out, dst, inp in wires:
            fmu, vr = fmus[dst]
            fmu.setReal([vr[inp].valueReference], [outputs[src][out]])
        if k >= steps - n:
            force[k - (steps - n)] = outputs["rig"]["measured_force"]  # the catenary's input this step
        for fmu, _ in fmus.values():
            fmu.doStep(currentCommunicationPoint=k * dt, communicationStepSize=dt)
        for name, (fmu, vr) in fmus.items():
            for out in outputs[name]:
                outputs[name][out] = fmu.getReal([vr[out].valueReference])[0]
    return force


def _release_fmus(fmus: dict) -> None:
    """Terminate and free every FMU instance, keeping the libraries loaded."""
    for fmu, _ in fmus.values():
        fmu.terminate()
        # free the instance but keep the library loaded: pythonfmu's binary owns Python objects
        # that can outlive the instance, and unloading it can crash the interpreter at exit
        fmu.fmi2FreeInstance(fmu.component)


def _compare_with_reference(cfg: dict, force: np.ndarray) -> int:
    """Write steady_span.csv, print the comparison with reference/ and return the exit code."""
    dt, steps, n = cfg["dt_s"], cfg["steps"], cfg["samples_per_span"]
    t = np.arange(n) * dt
    np.savetxt(HERE / "steady_span.csv", np.column_stack([t, force]), delimiter=",", header="t_s,f_N", comments="")
    reference = np.loadtxt(HERE / "reference" / "steady_span.csv", delimiter=",", skiprows=1)[:, 3]
    diff = float(np.max(np.abs(force - reference)))
    print(f"ran {steps} steps of {dt} s; converged span: mean {force.mean():.3f} N, std {force.std():.3f} N")
    print(f"max |f - reference| = {diff:.3e} N ({'OK' if diff <= cfg['tolerance_N'] else 'DIFFERS'}, "
          f"tolerance {cfg['tolerance_N']} N)")
    return 0 if diff <= cfg["tolerance_N"] else 1


def main() -> int:
    """Run the packaged SSP system with fmpy and compare the converged span with reference/; exit 1 if off."""
    cfg = json.loads((HERE / "system.json").read_text())
    ssp = HERE / cfg["ssp"]
    ssd = read_ssd(str(ssp))
    work = Path(tempfile.mkdtemp(prefix="pantohil_partner_"))
    try:
        with zipfile.ZipFile(ssp) as z:
            z.extractall(work / "ssp")
        values = _parameter_values(ssd)
        fmus = _instantiate_fmus(ssd, work, values)
        force = _co_simulate(ssd, fmus, cfg)
        _release_fmus(fmus)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return _compare_with_reference(cfg, force)


if __name__ == "__main__":
    sys.exit(main())
