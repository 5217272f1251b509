"""The kernel's IOPub channel keeps every message a slow reader has not yet taken.

Every widget reaches the page as IOPub messages (``comm_open``, ``comm_msg``); opening
the Workbench sends about 1,100 ``comm_open`` and 400 ``comm_msg`` in well under a
second. ipykernel 7 publishes them on a ZeroMQ XPUB socket (a PUB before 7) with
libzmq's default send high-water mark of 1,000 messages per subscriber, and a PUB/XPUB
socket that reaches it *drops* what it is handed, silently, until the subscriber (the
Jupyter server) catches up. On a busy machine the server falls behind during that
burst, an interior run of messages is lost while the ones around it arrive, and the
page shows "Error displaying widget: model not found" for any container whose child's
``comm_open`` was dropped (or a cell whose reply never comes). Measured here: a kernel
opening 20,000 comms while its reader is stalled delivers about 6,500 of them.

:func:`keep_every_iopub_message` raises that mark to :data:`IOPUB_HIGH_WATER_MARK`
(100,000 messages per subscriber). A server that falls behind by any burst the Workbench
makes then gets every message once it catches up; only a subscriber that stopped reading
altogether is ever dropped, so what a dead reader can hold in the kernel stays bounded
(100,000 of the Workbench's usual messages, a slider's or a GPU frame's parameters of about
1 KB, are about 100 MB; only full-geometry messages, which the GPU viewport sends once per
rig, are larger).
ipykernel has no setting for the mark and binds its socket at start-up, so it is raised at
run time: libzmq (4.3) applies a new mark to the pipes *already connected*, but a reader
that connects later (a reloaded page opens a new server connection) starts at the bind-time
default. Hence the mark is raised when ``widgets`` is imported and again just before each
large burst (building a :class:`~widgets.Workbench` or a rig studio). It runs on the IOPub
thread that owns the socket (ZeroMQ sockets are not thread-safe), queued with the messages
(``IOPubThread.schedule``), so every message sent after the call already has the new mark.

Tried and not used: ``ZMQ_XPUB_NODROP`` (nteract's launcher, PR 4188), which covers later
connections too but makes the kernel wait behind any client that connected and does not
read (a ``BlockingKernelClient`` that was never polled hung the next large cell). Posit's
ark kernel raised its IOPub mark to 100,000 for the same loss (ark PR 129).
"""

from __future__ import annotations

import logging
from typing import Any

#: messages a subscriber may fall behind before the kernel drops its IOPub messages
IOPUB_HIGH_WATER_MARK = 100_000
#: set on the kernel's IOPub thread to the mark it now has (for tests and diagnostics)
MARK_ATTR = "_fwb_iopub_high_water_mark"

log = logging.getLogger("widgets")


def raise_high_water_mark(socket: Any, mark: int = IOPUB_HIGH_WATER_MARK) -> int:
    """Let a ZeroMQ publisher queue ``mark`` messages per subscriber before it drops.

    Parameters
    ----------
    socket : zmq.Socket
        A PUB or XPUB socket, bound or not, used only from the calling thread.
    mark : int
        The send high-water mark (messages per subscriber); never lowered. Applied to
        every pipe connected now, each time (see the module docstring).

    Returns
    -------
    int
        The socket's send high-water mark now.
    """
    import zmq

    kind = socket.getsockopt(zmq.TYPE)
    if kind not in (zmq.PUB, zmq.XPUB):
        raise ValueError(f"socket: expected a PUB or XPUB ZeroMQ socket, got type {kind}")
    current = int(socket.getsockopt(zmq.SNDHWM))
    # set even when unchanged: libzmq re-applies the option to every connected pipe only
    # when it is set, and a pipe connected since the last call still has the old mark
    socket.setsockopt(zmq.SNDHWM, 0 if current == 0 else max(current, mark))  # 0: no limit
    return int(socket.getsockopt(zmq.SNDHWM))


def keep_every_iopub_message() -> bool:
    """Raise the running ipykernel's IOPub high-water mark (see the module docstring).

    Queued on the kernel's IOPub thread ahead of every message sent after this call; it
    reaches every reader connected at that moment. Cheap, so call it again before a
    large burst of widgets.

    Returns
    -------
    bool
        True when it was queued (or applied), False outside an ipykernel kernel (plain
        Python, a test without a kernel).
    """
    try:
        from ipykernel.kernelbase import Kernel
    except ImportError:
        return False
    if not Kernel.initialized():
        return False
    iopub = getattr(Kernel.instance(), "iopub_thread", None)
    socket = getattr(iopub, "socket", None)
    if iopub is None or socket is None or not hasattr(socket, "getsockopt"):
        return False

    def apply() -> None:
        try:
            setattr(iopub, MARK_ATTR, raise_high_water_mark(socket))
        except Exception:  # a closing kernel: nothing left to protect
            log.debug("could not raise the IOPub high-water mark", exc_info=True)

    iopub.schedule(apply)  # runs now where the IOPub thread is not running
    return True
