"""`pantohil run --live`: a Foxglove-protocol WebSocket client receives the channels of run.mcap, with
the same schemas and, step for step, the same values; the shipped layouts name only logged topics."""
from __future__ import annotations

import json
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

from conftest import PATIENT_LINK
from pantohil.orchestrator.live_layout import layout_topics

websockets_sync = pytest.importorskip("websockets.sync.client")

ROOT = Path(__file__).resolve().parents[2]
MESSAGE_DATA = 0x01  # Foxglove WebSocket protocol: binary opcode of a message on a subscription


def _start_live_run(out: Path, *args: str) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "run", "--out", str(out), "--quiet",
                             "--live", "127.0.0.1:0", "--live-wait", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for line in proc.stdout:  # wait on the server's line, not on time
        if "listening on" in line:
            return proc, line.split("listening on ")[1].split()[0]
    proc.wait()
    pytest.fail(f"no listening line: {proc.stderr.read()}")


def _receive_all(url: str) -> tuple[dict, dict]:
    """Subscribe to every advertised channel; collect messages until the server closes at the run's end."""
    channels, received = {}, {}
    with websockets_sync.connect(url, subprotocols=["foxglove.sdk.v1"], max_size=None) as ws:
        assert ws.subprotocol == "foxglove.sdk.v1"
        while not channels:
            msg = json.loads(ws.recv())
            if msg["op"] == "advertise":
                channels = {c["id"]: c for c in msg["channels"]}
        subs = {sub_id: ch for sub_id, ch in enumerate(channels.values(), start=1)}
        ws.send(
            json.dumps({"op": "subscribe", "subscriptions": [{"id": s, "channelId": c["id"]} for s, c in subs.items()]})
        )
        try:
            for frame in ws:
                if isinstance(frame, bytes) and frame[0] == MESSAGE_DATA:
                    sub_id, log_time_ns = struct.unpack_from("<IQ", frame, 1)
                    received.setdefault(subs[sub_id]["topic"], []).append((log_time_ns, frame[13:]))
        except websockets_sync.ConnectionClosed:
            pass
    return {c["topic"]: c for c in channels.values()}, received


def _mcap(path: Path) -> tuple[dict, dict]:
    schemas, messages = {}, {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            schemas[channel.topic] = (schema.name, schema.encoding, schema.data)
            messages.setdefault(channel.topic, {})[message.log_time] = message.data
    return schemas, messages


@pytest.mark.slow
@pytest.mark.network
@pytest.mark.realtime
def test_live_client_receives_the_logged_values(tmp_path):
    out = tmp_path / "run"
    proc, url = _start_live_run(out, "--set", "run.max_spans=4", "--realtime", "--rt-priority", "0")
    advertised, received = _receive_all(url)
    assert proc.wait(timeout=600) in (0, 1), proc.stderr.read()
    schemas, logged = _mcap(out / "run.mcap")
    assert set(advertised) == set(schemas)  # the same channels
    for topic, channel in advertised.items():
        name, encoding, data = schemas[topic]
        expected = ("ros2msg", "cdr") if topic not in ("/convergence", "/span_force") else ("jsonschema", "json")
        assert (channel["schemaName"], channel["schemaEncoding"], channel["encoding"]) == (name, *expected)
        assert encoding == expected[0] and channel["schema"].encode() == data
    assert set(received) == set(schemas), f"no live messages on {set(schemas) - set(received)}"
    for topic, messages in received.items():
        for log_time_ns, payload in messages:  # every live message is the logged one of the same step
            assert logged[topic][log_time_ns] == payload, topic
    live = json.loads((out / "summary.json").read_text())["live"]
    assert live["url"] == url and live["every_steps"] == 10 and live["viewer_subscribed"]
    assert live["published_messages"] >= sum(len(m) for m in received.values())
    steps = sorted(t for t, _ in received["/catenary"])
    dt_ns = 1_000_000
    assert all(t % (10 * dt_ns) == 0 for t in steps)  # 100 Hz of simulated time at dt = 1 ms
    assert len(received["/span_force"]) >= 2
    last = json.loads(received["/span_force"][-1][1])
    assert len(last["force_N"]) == len(last["previous_force_N"]) == 936


@pytest.mark.parametrize("topology", ["virtual", "hardware", "pair"])
def test_shipped_layouts_are_the_generated_ones(topology):
    from pantohil.orchestrator.live_layout import LAYOUT_FILES, layout_json

    assert (ROOT / "docs" / "foxglove" / LAYOUT_FILES[topology]).read_text() == layout_json(topology)


@pytest.mark.slow
def test_every_topic_of_the_layout_is_in_a_recorded_run(default_run):
    layout = json.loads((ROOT / "docs" / "foxglove" / "pantohil-layout.json").read_text())
    topics = layout_topics(layout)
    schemas, _ = _mcap(default_run / "run.mcap")
    assert {"/span_force", "/convergence", "/catenary", "/rig", "/pantograph"} <= topics
    assert topics <= set(schemas), f"layout topics not in run.mcap: {topics - set(schemas)}"


def _subscribe_all(ws) -> set[str]:
    """Subscribe to every advertised channel; the topics."""
    channels = []
    while not channels:
        msg = json.loads(ws.recv())
        channels = msg.get("channels", []) if msg["op"] == "advertise" else []
    ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": i, "channelId": c["id"]}
                                                             for i, c in enumerate(channels, 1)]}))
    return {c["topic"] for c in channels}


@pytest.mark.slow
@pytest.mark.network
@pytest.mark.realtime
def test_rig_run_with_a_stalled_viewer_ends_normally_and_logs_the_rig_layout_topics(tmp_path):
    emulator = subprocess.Popen([sys.executable, "-m", "pantohil.orchestrator.cli", "rig-emulator", "--listen",
                                 "127.0.0.1:0", "--rt-priority", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True)
    try:
        line = emulator.stdout.readline()
        assert "listening on" in line, emulator.stderr.read()
        rig = line.split("listening on ")[1].split()[0]
        out = tmp_path / "rig"
        # with a patient link a lost answer means that the stalled viewer held up the link
        proc, url = _start_live_run(out, "--hardware", rig, "--realtime", "--rt-priority", "0",
                                    "--set", "run.max_spans=3", "--set", PATIENT_LINK)
        # a viewer that subscribes and never reads again: its socket and the server's backlog fill up
        with websockets_sync.connect(url, subprotocols=["foxglove.sdk.v1"], max_size=None, max_queue=1) as ws:
            advertised = _subscribe_all(ws)
            _, err = proc.communicate(timeout=600)
    finally:
        emulator.terminate()
        emulator.wait(timeout=60)
    assert proc.returncode in (0, 1), err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["spans"] == 3 and summary["link"]["lost"] == 0
    schemas, _ = _mcap(out / "run.mcap")
    assert advertised == set(schemas) and {"/adapter", "/master"} <= advertised
    layout = json.loads((ROOT / "docs" / "foxglove" / "pantohil-rig-layout.json").read_text())
    assert layout_topics(layout) <= set(schemas), layout_topics(layout) - set(schemas)


def test_bad_live_endpoint_is_one_line_exit_2_and_no_run_folder(tmp_path):
    import socket

    from conftest import pantohil

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        in_use = f"127.0.0.1:{busy.getsockname()[1]}"
        for args in (["--live", "127.0.0.1:http"], ["--live", "127.0.0.1:70000"], ["--live-wait"],
                     ["--live", in_use], ["--live", "no-such-host.invalid:0"]):
            out = tmp_path / "run"
            proc = pantohil("run", "--out", str(out), "--quiet", *args)
            assert proc.returncode == 2 and proc.stderr.count("\n") == 1, (args, proc.stderr)
            assert "--live" in proc.stderr and not out.exists(), (args, proc.stderr)
