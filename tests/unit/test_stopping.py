"""The one signal path (orchestrator/stopping.py): 128 + the signal, a stop held back by a shielded block,
one interrupt only; an MCAP writer process that a stop signal never leaves waiting for half a message."""
from __future__ import annotations

import os
import signal
import threading

import numpy as np
import pytest
from mcap.reader import make_reader
from pantohil.orchestrator.recorder import McapRecorder
from pantohil.orchestrator.stopping import Interrupted, exit_code, shielded, signal_of, stop_on_signals


def test_exit_codes_are_128_plus_the_signal():
    assert [exit_code(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)] == [130, 143, 129]
    assert signal_of(KeyboardInterrupt()) == signal.SIGINT and signal_of(Interrupted(signal.SIGHUP)) == signal.SIGHUP


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_a_signal_in_a_shielded_block_interrupts_at_its_end_and_only_once(sig):
    reached = []
    with stop_on_signals(raising=True) as stop:
        with pytest.raises(Interrupted) as info, shielded():
            os.kill(os.getpid(), sig)
            reached.append("after the signal")
            os.kill(os.getpid(), sig)  # a second signal: counted, never a second interrupt
            reached.append("after the second")
        assert info.value.signum == sig and stop.count == 2
        os.kill(os.getpid(), sig)
        reached.append("after a third")
    assert reached == ["after the signal", "after the second", "after a third"]


def test_a_deferred_request_only_records_the_signal():
    with stop_on_signals(raising=True) as stop:
        stop.defer()  # `run`: the master checks the request between steps
        os.kill(os.getpid(), signal.SIGHUP)
        assert stop.requested and stop.signal_name == "SIGHUP"


def test_a_recorder_interrupted_while_sending_still_finishes_its_file(tmp_path):
    """D06: signals arrive while blocks larger than the pipe are being sent; the interrupt comes between
    two messages, never inside one, and close() finishes a complete file (it used to hang now and then)."""
    path = tmp_path / "run.mcap"
    recorder = McapRecorder(path, {"/a": {f"x{i}": "[m]" for i in range(4)}})
    rows = 200_000  # 6.4 MB a block: most of the time is spent inside send()
    t, columns = np.arange(rows) * 1e-3, np.random.default_rng(0).random((rows, 4))
    sent = threading.Event()
    with stop_on_signals(raising=True):
        def signal_while_sending():
            sent.wait(600)
            for _ in range(50):
                os.kill(os.getpid(), signal.SIGTERM)

        killer = threading.Thread(target=signal_while_sending)
        killer.start()
        with pytest.raises(Interrupted):
            for k in range(1000):
                if k == 1:
                    sent.set()
                recorder.write_block("/a", t + k * rows * 1e-3, columns)
        killer.join(600)
        recorder.close(timeout_s=600)
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == recorder.messages
        assert recorder.messages % rows == 0 and recorder.messages >= rows
