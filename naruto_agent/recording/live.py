"""Where a recording goes besides its file: a Rerun viewer reached while the episode runs.

``spawn`` starts a local viewer (the ``rerun`` executable the ``viewer`` extra installs) and
waits until it listens; a ``rerun+http://HOST:PORT/proxy`` address connects to a viewer
already running elsewhere. Either is checked before the episode starts, so that a viewer that
cannot be reached (no display, a wrong address) ends the run at once with a message saying
what to do, instead of an episode that streams into nothing or waits forever.
"""

from __future__ import annotations

import socket
import time
from urllib.parse import urlparse

#: The port a spawned viewer listens on (Rerun's default).
DEFAULT_PORT = 9876
RERUN_EXTRA_HINT = 'pip install "naruto-gym[viewer]"'


class LiveViewerError(RuntimeError):
    """No Rerun viewer could be reached for a live view; the message says what to do."""


def rerun_available() -> bool:
    """Whether the optional ``rerun-sdk`` (the ``viewer`` extra) is installed."""
    try:
        import rerun  # noqa: F401
    except ImportError:
        return False
    return True


def viewer_address(target: str) -> tuple[str, int, str]:
    """(host, port, gRPC url) of a live target: ``spawn``, ``HOST:PORT`` or a
    ``rerun+http://HOST:PORT/proxy`` url.

    Raises:
        ValueError: a target of none of these forms.
    """
    if target == "spawn":
        return "127.0.0.1", DEFAULT_PORT, f"rerun+http://127.0.0.1:{DEFAULT_PORT}/proxy"
    text = target if "://" in target else f"rerun+http://{target}/proxy"
    parsed = urlparse(text)
    try:
        port = parsed.port or DEFAULT_PORT
    except ValueError as error:
        raise ValueError(f"live viewer address {target!r} has a bad port: {error}") from error
    if not parsed.hostname or not parsed.scheme.startswith("rerun"):
        raise ValueError(
            f"live viewer address must be 'spawn', HOST:PORT or rerun+http://HOST:PORT/proxy, "
            f"got {target!r}"
        )
    return parsed.hostname, port, f"{parsed.scheme}://{parsed.hostname}:{port}/proxy"


def listening(host: str, port: int, timeout_s: float = 1.0) -> bool:
    """Whether something accepts TCP connections at ``host:port``."""
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return True
    except OSError:
        return False


def reach_viewer(target: str, wait_s: float = 15.0) -> str:
    """The gRPC url of a live viewer that answers, spawning one first for ``spawn``.

    Args:
        target: ``spawn`` or the address of a running viewer (see :func:`viewer_address`).
        wait_s: how long to wait for a spawned viewer to listen.

    Raises:
        LiveViewerError: the viewer is not installed, did not start, or does not answer.
    """
    if not rerun_available():
        raise LiveViewerError(f"the live view needs rerun-sdk: {RERUN_EXTRA_HINT}")
    host, port, url = viewer_address(target)
    if target != "spawn":
        if not listening(host, port, timeout_s=2.0):
            raise LiveViewerError(
                f"no Rerun viewer answers at {host}:{port}. Start one there (`rerun`), or "
                f"drop the address to spawn one here; the recording file is written anyway."
            )
        return url
    if not listening(host, port, timeout_s=0.5):
        import rerun as rr

        try:
            rr.spawn(port=port, connect=False)
        except Exception as error:  # noqa: BLE001 (any failure to start is the same to a user)
            raise LiveViewerError(f"could not start a Rerun viewer: {error}") from error
        deadline = time.monotonic() + wait_s
        while not listening(host, port, timeout_s=0.5):
            if time.monotonic() > deadline:
                raise LiveViewerError(
                    f"a Rerun viewer was started but did not listen on port {port} within "
                    f"{wait_s:.0f} s (no display on this machine?). Run `rerun` where there is "
                    f"a screen and stream to it with its address, or open the recording file "
                    f"afterwards with `rerun FILE.rrd`."
                )
            time.sleep(0.25)
    return url
