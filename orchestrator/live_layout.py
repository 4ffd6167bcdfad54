"""The Foxglove layouts shipped in docs/foxglove/, built with foxglove-sdk's layout types: the same
panels for a live run (`pantohil run --live`) and for its run.mcap, since both carry the same topics.

    python -m pantohil.orchestrator.live_layout docs/foxglove   # writes both layout files

pantohil-layout.json is for virtual runs (/rig, /pantograph); pantohil-rig-layout.json for runs on a
rig (`--hardware`: /adapter, with the link's counters and state); pantohil-pair-layout.json for virtual runs
of two pantographs (also /pantograph_2 and the catenary's second contact point).
"""
from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import foxglove.layouts as fl

LAYOUT_FILES = {"virtual": "pantohil-layout.json", "hardware": "pantohil-rig-layout.json",
                "pair": "pantohil-pair-layout.json"}
LINK_COUNTERS = ("lost", "late", "reordered", "duplicated", "malformed", "limited")


def _plot(title: str, series: list[tuple[str, str]], **config) -> fl.PlotPanel:
    return fl.PlotPanel(title=title, config=fl.PlotConfig(
        paths=[fl.PlotSeries(value=path, label=label, enabled=True) for path, label in series],
        show_legend=True, legend_display="floating", **config))


def _row(*panels, proportions=None) -> fl.SplitContainer:
    proportions = proportions or [1] * len(panels)
    return fl.SplitContainer(direction="row", items=[fl.SplitItem(proportion=p, content=c)
                                                     for p, c in zip(proportions, panels, strict=False)])


def _convergence_row() -> fl.SplitContainer:
    span = _plot("Contact force of the span: current over previous [N] against the sample",
                 [("/span_force.force_N[:]", "current span"), ("/span_force.previous_force_N[:]", "previous span")],
                 x_axis_val="index", x_axis_label="sample of the span")
    change = _plot("Span-to-span change (RMS over std)", [("/convergence.change", "change")])
    stats = _plot("Span mean and std [N]", [("/convergence.mean_N", "mean"), ("/convergence.std_N", "std")])
    return _row(span, change, stats, proportions=[2, 1, 1])


def build_layout(topology: str) -> fl.Layout:
    """The panels: span force overlay, convergence, per-step force and actuator height (and link)."""
    if topology == "virtual":
        force = _plot("Contact force per step [N]", [("/catenary.force_at_sample", "force in use"),
                                                      ("/pantograph.contact_force", "pantograph contact")])
        height = _plot("Actuator height [m]", [("/rig.actuator_height", "actuator"),
                                               ("/catenary.height_command", "commanded")])
        bottom = _row(force, height, fl.RawMessagesPanel(title="Last span",
                                                         config=fl.RawMessagesConfig(topic_path="/convergence")))
    elif topology == "pair":
        force = _plot("Contact force per step [N]", [("/catenary.force_at_sample", "first, in use"),
                                                      ("/pantograph.contact_force", "first pantograph"),
                                                      ("/catenary.force_at_sample_2", "second, in use"),
                                                      ("/pantograph_2.contact_force", "second pantograph")])
        height = _plot("Commanded heights [m]", [("/catenary.height_command", "first"),
                                                 ("/catenary.height_command_2", "second"),
                                                 ("/rig.actuator_height", "first's actuator")])
        bottom = _row(force, height, fl.RawMessagesPanel(title="Last span",
                                                         config=fl.RawMessagesConfig(topic_path="/convergence")))
    elif topology == "hardware":
        force = _plot("Contact force per step [N]", [("/catenary.force_at_sample", "force in use"),
                                                      ("/adapter.measured_force", "measured on the rig")])
        height = _plot("Actuator height [m] (command within the actuator limits)",
                       [("/adapter.command_sent", "sent"), ("/adapter.actuator_height", "reported by the rig"),
                        ("/catenary.height_command", "commanded")])
        link = _plot("Link counters [-] and state (0 ok, 1 missing, 2 fault)",
                     [(f"/adapter.{c}", c) for c in LINK_COUNTERS] + [("/adapter.link_state", "state")])
        bottom = _row(force, height, link)
    else:
        raise ValueError(f"topology must be one of {', '.join(LAYOUT_FILES)} (got {topology!r})")
    return fl.Layout(content=fl.SplitContainer(direction="column", items=[
        fl.SplitItem(proportion=1, content=_convergence_row()), fl.SplitItem(proportion=1, content=bottom)]))


def layout_json(topology: str) -> str:
    """The Foxglove layout of a topology ("virtual", "hardware" or "pair") as JSON text."""
    return json.dumps(json.loads(build_layout(topology).to_json()), indent=2) + "\n"


_TOPIC = re.compile(r"^(/[A-Za-z0-9_/]+?)(?=[.\[{]|$)")


def layout_topics(layout: dict) -> set[str]:
    """Every topic a layout names: the message paths of its plots and the topic of its other panels."""
    topics = set()

    def walk(node):
        if isinstance(node, dict):
            for key, value in node.items():
                if key in ("value", "topicPath") and isinstance(value, str) and (m := _TOPIC.match(value)):
                    topics.add(m.group(1))
                walk(value)
        elif isinstance(node, list):
            for item in node:
                walk(item)

    walk(layout)
    return topics


def main(argv: list[str] | None = None) -> int:
    """Write the shipped Foxglove layouts into a folder (default docs/foxglove)."""
    folder = Path((argv or sys.argv[1:] or ["docs/foxglove"])[0])
    folder.mkdir(parents=True, exist_ok=True)
    for topology, name in LAYOUT_FILES.items():
        (folder / name).write_text(layout_json(topology))
        print(folder / name)
    return 0


if __name__ == "__main__":
    sys.exit(main())
