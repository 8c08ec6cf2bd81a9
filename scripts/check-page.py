#!/usr/bin/env python3
"""Checks the web page of targets/wasm in headless Chromium, in real time (performance.now()
must measure the model's steps, which a virtual clock would not advance), through the DevTools
protocol over a pipe (standard library only).

    scripts/check-page.py URL OUTDIR [--frames N] [--expect NAME ...]

Opens URL (the page with ?test=1), then chooses every model the page offers in its <select>,
the way a person does (the value set, a change event), and waits until the page has stepped and
drawn N frames of it. For each model it prints the page's line

    page: model=NAME frames=N moved=D status=S drawn=P ms=T pushed=K

and saves a screenshot OUTDIR/wasm-page-NAME.png (the first model's also as
OUTDIR/wasm-page.png). Fails (exit 1) when a model does not load, its frames do not advance,
its surface does not move (D <= 1e-3 of the diagonal), a step is refused (S < 0), less than
1% of the canvas is drawn (P, pixels read back that are not background), no time per frame
is reported (T <= 0), the ball the synthetic mouse sweeps through the body from frame 60 pushed
no drawn vertex out (K = 0: the run-time collider did not reach the surface), or a model named
with --expect is not offered.
"""

import argparse
import base64
import fcntl
import json
import os
import re
import subprocess
import sys
import tempfile
import time

LINE = re.compile(r"model=(\S+) frames=(\d+) moved=([0-9.]+) status=(-?\d+) drawn=(\d+) ms=([0-9.]+) pushed=(\d+)")


class Browser:
    """Headless Chromium driven over --remote-debugging-pipe (fd 3 in, fd 4 out)."""

    def __init__(self, profile):
        to_browser, self.commands = os.pipe()
        self.replies, from_browser = os.pipe()

        def pipes():
            # Out of the way first: either end may itself be fd 3 or 4.
            high = [fcntl.fcntl(fd, fcntl.F_DUPFD, 10) for fd in (to_browser, from_browser)]
            for fd, target in zip(high, (3, 4)):
                os.dup2(fd, target)

        args = ["chromium", "--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--no-first-run", f"--user-data-dir={profile}", "--window-size=840,860",
                "--remote-debugging-pipe"]
        self.process = subprocess.Popen(args, preexec_fn=pipes, close_fds=False,
                                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(to_browser)
        os.close(from_browser)
        self.next_id = 0
        self.buffer = b""
        self.attached_id = None

    def call(self, method, params=None, to_target=True):
        self.next_id += 1
        message = {"id": self.next_id, "method": method, "params": params or {}}
        if to_target and self.attached_id:
            message["sessionId"] = self.attached_id
        os.write(self.commands, json.dumps(message).encode() + b"\0")
        while True:
            while b"\0" not in self.buffer:
                chunk = os.read(self.replies, 1 << 20)
                if not chunk:
                    raise RuntimeError("the browser closed its pipe")
                self.buffer += chunk
            raw, self.buffer = self.buffer.split(b"\0", 1)
            reply = json.loads(raw)
            if reply.get("id") == self.next_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def open(self, url):
        target = self.call("Target.createTarget", {"url": "about:blank"}, to_target=False)["targetId"]
        self.attached_id = self.call("Target.attachToTarget", {"targetId": target, "flatten": True},
                                 to_target=False)["sessionId"]
        self.call("Page.enable")
        self.call("Page.navigate", {"url": url})

    def evaluate(self, expression):
        result = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True})
        if "exceptionDetails" in result:
            raise RuntimeError(f"{expression}: {result['exceptionDetails']}")
        return result.get("result", {}).get("value")

    def screenshot(self, path):
        data = self.call("Page.captureScreenshot", {"format": "png"})["data"]
        with open(path, "wb") as f:
            f.write(base64.b64decode(data))

    def close(self):
        try:
            self.call("Browser.close", to_target=False)
        except (RuntimeError, OSError):
            pass
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()


STATUS = "document.getElementById('status')?.textContent ?? ''"


def wait_for(browser, name, frames, seconds):
    """The page's line once model NAME has drawn FRAMES frames."""
    deadline = time.monotonic() + seconds
    line = ""
    while time.monotonic() < deadline:
        line = browser.evaluate(STATUS) or ""
        if line.startswith("error"):
            break
        m = LINE.search(line)
        if m and (name is None or m.group(1) == name) and int(m.group(2)) >= frames:
            return line
        time.sleep(0.2)
    sys.exit(f"page: model {name or '(first)'} did not reach {frames} frames: {line!r}")


def check(line):
    m = LINE.search(line)
    name, moved, status, drawn, ms = m.group(1), float(m.group(3)), int(m.group(4)), int(m.group(5)), float(m.group(6))
    pushed = int(m.group(7))
    width, height = 800, 480
    problems = []
    if not moved > 1e-3:
        problems.append("the surface did not move")
    if status < 0:
        problems.append("the last step was refused")
    if drawn < 0.01 * width * height:
        problems.append("less than 1% of the canvas is drawn")
    if not ms > 0:
        problems.append("no time per frame")
    if pushed == 0:
        problems.append("the ball pushed no drawn vertex out")
    return name, problems


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("url")
    parser.add_argument("out")
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--expect", nargs="*", default=[])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as profile:
        browser = Browser(profile)
        try:
            browser.open(args.url)
            first = wait_for(browser, None, args.frames, 120)
            offered = browser.evaluate("[...document.getElementById('model').options].map((o) => o.value)") or []
            failed = [f"model {e} is not offered (offered: {offered})" for e in args.expect if e not in offered]
            # The first model shown, then every other one in the page's order.
            shown = LINE.search(first).group(1)
            order = [shown] + [name for name in offered if name != shown]
            for i, name in enumerate(order):
                if i > 0:
                    browser.evaluate("(() => { const s = document.getElementById('model');"
                                     f" s.value = {json.dumps(name)}; s.dispatchEvent(new Event('change')); }})()")
                line = wait_for(browser, name, args.frames, 120)
                print(f"page: {line}", flush=True)
                browser.screenshot(os.path.join(args.out, f"wasm-page-{name}.png"))
                if i == 0:
                    browser.screenshot(os.path.join(args.out, "wasm-page.png"))
                _, problems = check(line)
                failed += [f"model {name}: {p}" for p in problems]
        finally:
            browser.close()
    if failed:
        sys.exit("page check failed:\n  " + "\n  ".join(failed))


if __name__ == "__main__":
    main()
