"""The kernel's IOPub channel keeps every message a reader that fell behind has not taken.

A ZeroMQ PUB/XPUB socket silently drops what it is handed once a subscriber is a
high-water mark behind (libzmq's default: 1,000 messages). A Workbench build is about
1,500 messages, so a Jupyter server that stalls on a busy machine lost some, and the page
showed "model not found" (``widgets._iopub``). Checked here on plain sockets (the default
loses, the raised mark does not) and in a real ipykernel (a reader that connects after
``import widgets`` and stalls during a burst of 20,000 comms gets every one).
"""

from __future__ import annotations

import threading
import time

import pytest

zmq = pytest.importorskip("zmq")

from widgets._iopub import IOPUB_HIGH_WATER_MARK, raise_high_water_mark  # noqa: E402

BURST = 20_000


def _pair(kind: int) -> tuple[object, object, object]:
    ctx = zmq.Context()
    pub = ctx.socket(kind)
    # small fixed TCP buffers (no autotuning): what the kernel buffers is then the mark's doing,
    # on any machine
    pub.setsockopt(zmq.SNDBUF, 1 << 16)
    port = pub.bind_to_random_port("tcp://127.0.0.1")
    sub = ctx.socket(zmq.SUB)
    sub.setsockopt(zmq.RCVBUF, 1 << 16)
    sub.setsockopt(zmq.SUBSCRIBE, b"")
    sub.connect(f"tcp://127.0.0.1:{port}")
    return ctx, pub, sub


def _wait_subscribed(pub: object, sub: object) -> None:
    """Until the subscription is in place (an XPUB reports it; a PUB is probed)."""
    if pub.getsockopt(zmq.TYPE) == zmq.XPUB:
        assert pub.poll(10_000), "the subscription never reached the XPUB"
        assert pub.recv() == b"\x01"
        return
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        pub.send(b"probe")
        if sub.poll(50):
            while sub.poll(50):
                sub.recv()
            return
    raise AssertionError("the subscriber never received a probe")


def _burst_with_a_stalled_reader(pub: object, sub: object) -> int:
    """Publish BURST messages while the subscriber reads nothing; then count what arrives."""
    payload = b"x" * 2000  # 40 MB in all: far more than the TCP buffers hold
    for i in range(BURST):
        pub.send_multipart([str(i).encode(), payload])
    got = 0
    while sub.poll(2000):
        sub.recv_multipart()
        got += 1
    return got


@pytest.mark.parametrize("kind", ["XPUB", "PUB"])
def test_the_default_mark_drops_and_the_raised_one_keeps_every_message(kind: str) -> None:
    kind_id = getattr(zmq, kind)
    ctx, pub, sub = _pair(kind_id)
    try:
        _wait_subscribed(pub, sub)
        lost = _burst_with_a_stalled_reader(pub, sub)
        assert lost < BURST, "libzmq's default mark kept everything: the burst proves nothing"
    finally:
        ctx.destroy(linger=0)
    ctx, pub, sub = _pair(kind_id)
    try:
        _wait_subscribed(pub, sub)
        assert raise_high_water_mark(pub) == IOPUB_HIGH_WATER_MARK  # on a pipe already connected
        assert _burst_with_a_stalled_reader(pub, sub) == BURST
    finally:
        ctx.destroy(linger=0)


def test_the_mark_is_never_lowered_and_other_sockets_are_refused() -> None:
    ctx = zmq.Context()
    try:
        pub = ctx.socket(zmq.XPUB)
        pub.setsockopt(zmq.SNDHWM, 0)  # "no limit" stays no limit
        assert raise_high_water_mark(pub) == 0
        pub.setsockopt(zmq.SNDHWM, 2 * IOPUB_HIGH_WATER_MARK)
        assert raise_high_water_mark(pub) == 2 * IOPUB_HIGH_WATER_MARK
        with pytest.raises(ValueError, match="socket: expected a PUB or XPUB"):
            raise_high_water_mark(ctx.socket(zmq.PUSH))
    finally:
        ctx.destroy(linger=0)


def test_outside_a_kernel_nothing_happens() -> None:
    from widgets._iopub import keep_every_iopub_message

    assert keep_every_iopub_message() is False


def test_a_kernel_that_imported_widgets_delivers_a_burst_to_a_reader_that_stalled() -> None:
    """The real path: ipykernel's XPUB, a reader connected after ``import widgets``."""
    pytest.importorskip("ipykernel")
    from jupyter_client import KernelManager

    km = KernelManager(kernel_name="python3")
    km.start_kernel()
    kc = km.client()
    try:
        kc.start_channels()
        kc.wait_for_ready(timeout=120)
        reply = kc.execute_interactive("import widgets", timeout=120)
        assert reply["content"]["status"] == "ok", reply["content"]
        late = km.connect_iopub()  # like a page that connects to a running kernel
        time.sleep(0.5)
        got = [0]

        def reader() -> None:
            time.sleep(3.0)  # the server is busy elsewhere while the burst is sent
            while late.poll(3000):
                if b'"comm_open"' in b"".join(late.recv_multipart()[:5]):
                    got[0] += 1

        t = threading.Thread(target=reader)
        t.start()
        code = (
            "import comm, widgets\n"
            "widgets.keep_every_iopub_message()  # what the Workbench does before its burst\n"
            f"_cs = [comm.create_comm(target_name='probe', data={{'i': i}}) for i in range({BURST})]\n"
        )
        # the shell reply is read in parallel with the client's own IOPub (execute_interactive)
        reply = kc.execute_interactive(code, timeout=180, output_hook=lambda _m: None)
        assert reply["content"]["status"] == "ok", reply["content"]
        t.join(timeout=120)
        assert got[0] == BURST
        late.close(linger=0)
    finally:
        kc.stop_channels()
        km.shutdown_kernel(now=True)
