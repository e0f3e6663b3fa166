"""Headless Chromium for the tests, driven over the DevTools protocol (standard library only).

:class:`DevTools` starts Debian's ``chromium`` with ``--remote-debugging-pipe`` (fd 3:
commands in, fd 4: replies and events out, JSON messages separated by NUL bytes),
loads pages, evaluates JavaScript, lists console errors, exceptions, error log entries
and external requests (:meth:`DevTools.problems`) and takes full-page screenshots.
:func:`chromium_or_skip` finds the browser, or skips the test (fails it with
``VARFLOW_REQUIRE_BROWSER=1``, as in CI).  Used by the report's and the
documentation's tests.
"""

from __future__ import annotations

import base64
import contextlib
import io
import json
import os
import queue
import shutil
import signal
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image


def chromium_or_skip() -> str:
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None and Path("/usr/bin/chromium").exists():
        exe = "/usr/bin/chromium"
    if exe is None:
        msg = ("headless Chromium not found (apt-get install chromium); the pages' "
               "rendering is not tested")
        if os.environ.get("VARFLOW_REQUIRE_BROWSER", "").strip() == "1":
            pytest.fail(msg)
        pytest.skip(msg)
    return exe


class DevTools:
    """Headless Chromium driven over ``--remote-debugging-pipe`` (fd 3: commands in,
    fd 4: replies and events out, JSON messages separated by NUL bytes)."""

    TIMEOUT = 30.0

    def __init__(self, exe: str, workdir: Path, width: int = 1280, height: int = 1000) -> None:
        self.workdir = workdir
        cmd_r, cmd_w = os.pipe()
        evt_r, evt_w = os.pipe()
        # move the child's ends out of the way of fds 3/4 before bash redirects them (dash
        # only knows single-digit descriptors)
        import fcntl

        child_r = fcntl.fcntl(cmd_r, fcntl.F_DUPFD, 20)
        child_w = fcntl.fcntl(evt_w, fcntl.F_DUPFD, 20)
        os.close(cmd_r)
        os.close(evt_w)
        self.command_line = [
            exe, "--headless", "--no-sandbox", "--disable-gpu",
            f"--user-data-dir={workdir / 'profile'}", "--remote-debugging-pipe",
            "--no-first-run", "--no-default-browser-check", "--disable-extensions",
            "--force-device-scale-factor=1", "--force-color-profile=srgb", "--hide-scrollbars",
            f"--window-size={width},{height}", "about:blank",
        ]
        self.stderr = open(workdir / "chromium.log", "wb")  # noqa: SIM115
        self.proc = subprocess.Popen(
            [shutil.which("bash") or "/bin/bash", "-c",
             f'exec "$@" 3<&{child_r} 4>&{child_w} {child_r}<&- {child_w}>&-',
             "bash", *self.command_line],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=self.stderr,
            pass_fds=(child_r, child_w), start_new_session=True,
        )
        os.close(child_r)
        os.close(child_w)
        self._out = os.fdopen(cmd_w, "wb", buffering=0)
        self._in = evt_r
        self._queue: queue.Queue[dict[str, Any] | None] = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self._next_id = 0
        self.events: list[dict[str, Any]] = []
        self.session: str | None = None
        try:
            target = self.send("Target.createTarget", {"url": "about:blank"}, browser=True)
            attached = self.send("Target.attachToTarget",
                                 {"targetId": target["targetId"], "flatten": True},
                                 browser=True)
            self.session = attached["sessionId"]
            for domain in ("Runtime", "Log", "Page", "Network"):
                self.send(f"{domain}.enable")
        except BaseException:
            self.close()
            raise

    def _read(self) -> None:
        buf = b""
        while True:
            try:
                chunk = os.read(self._in, 1 << 16)
            except OSError:
                chunk = b""
            if not chunk:
                self._queue.put(None)
                return
            buf += chunk
            while b"\0" in buf:
                msg, buf = buf.split(b"\0", 1)
                self._queue.put(json.loads(msg))

    def _get(self, deadline: float) -> dict[str, Any]:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise TimeoutError("no answer from Chromium")
        try:
            msg = self._queue.get(timeout=remaining)
        except queue.Empty:
            raise TimeoutError("no answer from Chromium") from None
        if msg is None:
            log = (self.workdir / "chromium.log").read_text(errors="replace")[-2000:]
            raise RuntimeError(f"Chromium closed the pipe; log tail:\n{log}")
        return msg

    def send(self, method: str, params: dict[str, Any] | None = None,
             browser: bool = False) -> dict[str, Any]:
        self._next_id += 1
        msg: dict[str, Any] = {"id": self._next_id, "method": method, "params": params or {}}
        if not browser:
            msg["sessionId"] = self.session
        self._out.write(json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + self.TIMEOUT
        while True:
            reply = self._get(deadline)
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})
            if "method" in reply:
                self.events.append(reply)

    def wait_event(self, method: str, timeout: float = TIMEOUT) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        for i, e in enumerate(self.events):
            if e["method"] == method:
                return self.events.pop(i)
        while True:
            msg = self._get(deadline)
            if msg.get("method") == method:
                return msg
            if "method" in msg:
                self.events.append(msg)

    def drain(self, seconds: float) -> None:
        """Collect the events arriving during ``seconds``."""
        deadline = time.monotonic() + seconds
        while True:
            try:
                msg = self._get(deadline)
            except TimeoutError:
                return
            if "method" in msg:
                self.events.append(msg)

    def load(self, url: str) -> None:
        self.events.clear()
        self.send("Page.navigate", {"url": url})
        self.wait_event("Page.loadEventFired")
        self.drain(0.5)  # late console messages

    def evaluate(self, expression: str) -> Any:
        result = self.send("Runtime.evaluate", {"expression": expression,
                                                "returnByValue": True})
        assert "exceptionDetails" not in result, result
        return result["result"].get("value")

    def problems(self) -> list[str]:
        """Console errors/warnings, uncaught exceptions, error log entries, external requests."""
        found = []
        for e in self.events:
            p = e.get("params", {})
            if e["method"] == "Runtime.consoleAPICalled" and p.get("type") in (
                    "error", "assert", "warning"):
                found.append("console." + p["type"] + ": " + " ".join(
                    str(a.get("value", a.get("description", ""))) for a in p.get("args", [])))
            elif e["method"] == "Runtime.exceptionThrown":
                d = p.get("exceptionDetails", {})
                found.append("exception: " + str(d.get("exception", {}).get("description")
                                                 or d.get("text")))
            elif e["method"] == "Log.entryAdded" and p["entry"]["level"] in ("error", "warning"):
                found.append(f"log {p['entry']['level']}: {p['entry']['text']}")
            elif e["method"] == "Network.requestWillBeSent":
                url = p["request"]["url"]
                if not url.startswith(("data:", "file:")):
                    found.append(f"request: {url}")
        return found

    def screenshot(self) -> np.ndarray:
        """Full-page screenshot at 1 CSS pixel = 1 image pixel."""
        width, height = self.evaluate(
            "[document.documentElement.scrollWidth, document.documentElement.scrollHeight]")
        self.send("Emulation.setDeviceMetricsOverride",
                  {"width": int(width), "height": int(min(height, 12000)),
                   "deviceScaleFactor": 1, "mobile": False})
        data = self.send("Page.captureScreenshot", {"format": "png"})["data"]
        with Image.open(io.BytesIO(base64.b64decode(data))) as im:
            return np.asarray(im.convert("RGB"))

    def close(self) -> None:
        try:
            if self.proc.poll() is None:
                self._out.write(json.dumps({"id": 0, "method": "Browser.close"}).encode()
                                + b"\0")
            self.proc.wait(timeout=10)
        except (OSError, subprocess.TimeoutExpired):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGKILL)  # our own process group only
            self.proc.wait(timeout=10)
        finally:
            self._out.close()
            self.stderr.close()
            self._reader.join(timeout=5)  # it stops at the end of the pipe
            os.close(self._in)
