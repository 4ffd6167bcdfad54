"""The page an FMU carries in documentation/index.html: what it is, its method, its limits, how to run it
and its variables."""
from __future__ import annotations

import html

LIMITS = ("The periodic method gives the steady state of a pantograph running along an endless line of equal "
          "spans: no overlaps, section ends, local irregularities or curves. The HIL iteration converges only "
          "where it is stable: keep the highest harmonic below the pantograph's contact frequency, or the loop "
          "delay short (Gil et al., Paper D sec. 4).")


def documentation_page(name: str, variables, description: str, method: str) -> str:
    """The HTML page of FMU `name`: its description, method (the FMU script's docstring), limits, the wiring
    of the virtual HIL and a table of its variables."""
    rows = "".join(f"<tr><td>{html.escape(v.name)}</td><td>{v.causality}</td><td>{html.escape(v.unit)}</td>"
                   f"<td>{html.escape(v.description)}</td></tr>" for v in variables)
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>pantohil {name}</title></head><body>"
            f"<h1>pantohil {name} FMU</h1><p>{html.escape(description)}</p>"
            f"<h2>Method</h2><p>{html.escape(method)}</p><h2>Limits</h2><p>{html.escape(LIMITS)}</p>"
            "<h2>Running it</h2><p>FMI 2.0 co-simulation, built with pythonfmu: the host needs Python 3.11 with "
            "numpy and scipy (resources/requirements.txt). Case data are the start values, also in "
            "resources/parameters.json. Connect catenary.height_command to rig.height_command, "
            "rig.actuator_height to pantograph.height, pantograph.contact_force to rig.true_force and "
            "rig.measured_force to catenary.contact_force; set catenary.delay_steps to the loop latency of "
            "the master plus rig.latency_steps.</p><h2>Variables</h2>"
            f"<table border='1'><tr><th>variable</th><th>causality</th><th>unit</th><th>description</th></tr>{rows}"
            "</table></body></html>")
