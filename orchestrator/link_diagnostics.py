"""What a hardware run says about its rig link: the counters kept in summary.json, why a session start
was refused, and why a link went into fault."""
from __future__ import annotations

from pantohil.fmus import link_client
from pantohil.models.case import Case

LINK_OK, LINK_FAULT = link_client.LINK_OK, link_client.LINK_FAULT
LINK_COUNTERS = (*link_client.COUNTERS, *link_client.TICK_COUNTS)
RIG_PACED_COUNTERS = tuple(link_client.RIG_PACED_COUNTERS)
REFUSALS = {1: "it speaks another protocol version", 2: "it refused the session start (bad HELLO)",
            4: "it is busy with another session", 8: "it does not run that pacing (link.paced_by)",
            16: "it does not take a horizon of link.horizon_steps heights",
            link_client.REFUSED_LATENCY: "its STATUS reported a latency outside 0..100000 steps",
            link_client.REFUSED_HORIZON: "its STATUS granted no horizon, or more than link.horizon_steps"}


def link_summary(master, case: Case, hardware: tuple, rig_paced: bool, scheduling: str, answer_us) -> dict:
    """summary.json's `link`: the adapter's counters after the last step, the pacing, the rig's address and
    latency, and (rig-paced) the answer times' percentiles."""
    last = max(master.k - 1, 0)
    counters = LINK_COUNTERS + (RIG_PACED_COUNTERS if rig_paced else ())
    link = {c: master.int_value("adapter", c, last) for c in counters}
    link["paced_by"] = case.sections.link.paced_by
    if rig_paced:
        link["scheduling"] = scheduling
        link["answer_us"] = {q: answer_us.summary()[q] for q in ("p50", "p99", "max")}
    link["rig"] = f"{hardware[0]}:{hardware[1]}"
    link["rig_latency_steps"] = master.int_value("adapter", "rig_latency_steps", last)
    return link


def link_fault_reason(case: Case, rig_paced: bool) -> str:
    """Why the adapter put the link into fault, in the keys that set its tolerance."""
    link = case.sections.link
    if rig_paced:
        return (f"no sample from the rig for link.sample_timeout_s = {link.sample_timeout_s:g} s, or more than "
                f"{link.tolerated_losses} consecutive samples missing")
    return f"more than {link.tolerated_losses} consecutive answers missing"


def session_refused(refusal: int, hardware: tuple) -> str:
    """The rig's refusal bits (REFUSALS) as a sentence."""
    why = "; ".join(text for bit, text in REFUSALS.items() if refusal & bit) or "it did not answer"
    return f"the rig at {hardware[0]}:{hardware[1]} did not accept the session start: {why}"


def session_start_refusal(master, hardware: tuple) -> str | None:
    """After initialisation (masters that can be asked before stepping): why the rig did not accept the
    session, or None if it did."""
    values = master.instances["adapter"].get_values(["link_state", "session_started", "rig_refusal"])
    if values["link_state"] == LINK_FAULT and not values["session_started"]:
        return session_refused(int(values["rig_refusal"]), hardware)
    return None
