#!/usr/bin/env python3
"""Drives the live dashboard in headless Chromium over the Chrome DevTools
Protocol (Python `websockets`), during a `fleet up --dashboard`.

Usage: dashboard_check.py URL TOKEN ROBOTS [--states JSON] [--resume]

1. Opens URL without the token (read-only): waits until ROBOTS robots are
   drawn, checks the Stop all button is disabled and that the server
   refuses the page's stop (its HTTP status).
2. Samples, 20 times 50 ms apart, what the page drew: per robot the world
   position of the drawn robot and the time of the state it drew; reads
   the robots' table as shown; with --states, the table cells the page
   makes of each of those states (`dashboard.cells(k, state, null, age)`,
   JSON `[[k, state, age], ...]`).
3. Opens URL?token=TOKEN and presses Stop all with real mouse events;
   notes the UNIX time (ms) of the press and the server's answer (status
   and, when 200, the command put and who acknowledged it); with --resume,
   one second later presses Resume the same way.

Prints one JSON object: {"readonly": {"disabled": bool, "status": int},
"samples": [[k, t, x, y], ...], "table": [[cell, ...], ...], "cells":
[[cell, ...], ...], "stop": {"pressed_ms": ms, "status": int, "outcome":
{...}}, "resume": {...} (with --resume), "errors": [console errors and
exceptions]}.
"""

import argparse
import contextlib
import json
import os
import re
import subprocess
import tempfile
import threading
import time

from websockets.sync.client import connect


class Page:
    def __init__(self, stack, browser_ws, url):
        self.browser = stack.enter_context(connect(browser_ws, max_size=None))
        self.next_id = 0
        self.errors = []
        target = self.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        self.session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        self.call("Runtime.enable", session=True)
        self.call("Page.enable", session=True)
        self.call("Page.navigate", {"url": url}, session=True)

    def call(self, method, params=None, session=False):
        self.next_id += 1
        msg = {"id": self.next_id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = self.session
        self.browser.send(json.dumps(msg))
        while True:
            reply = json.loads(self.browser.recv(timeout=30))
            if reply.get("method") == "Runtime.exceptionThrown":
                self.errors.append(reply["params"]["exceptionDetails"].get("text", "exception"))
            if reply.get("method") == "Runtime.consoleAPICalled" and reply["params"]["type"] == "error":
                self.errors.append(str(reply["params"]["args"]))
            if reply.get("id") == self.next_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply["result"]

    def eval(self, expr, wait=False):
        r = self.call("Runtime.evaluate", {"expression": expr, "returnByValue": True,
                                           "awaitPromise": wait}, session=True)
        if "exceptionDetails" in r:
            raise RuntimeError(f"{expr}: {r['exceptionDetails']}")
        return r["result"].get("value")

    def until(self, expr, seconds=60):
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            try:
                if self.eval(expr):
                    return
            except RuntimeError:
                pass
            time.sleep(0.05)
        raise RuntimeError(f"not within {seconds} s: {expr}")

    def click(self, element_id):
        box = self.eval(f"(() => {{ const r = document.getElementById('{element_id}')"
                        ".getBoundingClientRect(); return [r.x + r.width / 2, r.y + r.height / 2]; })()")
        for kind in ["mousePressed", "mouseReleased"]:
            self.call("Input.dispatchMouseEvent", {"type": kind, "x": box[0], "y": box[1],
                                                   "button": "left", "clickCount": 1}, session=True)


def press(page, button, nth):
    """Presses `button`; when it pressed, the server's answer."""
    pressed = time.time() * 1000.0
    page.click(button)
    page.until(f"dashboard.orders.length >= {nth}", 10)
    status = page.eval(f"dashboard.orders[{nth - 1}][1]")
    outcome = page.eval("dashboard.outcomes[dashboard.outcomes.length - 1] || null")
    return {"pressed_ms": pressed, "status": status, "outcome": outcome if status == 200 else None}


def main(url, token, robots, states, resume):
    chromium = os.environ.get("ECHELON_CHROMIUM", "/usr/bin/chromium")
    profile = tempfile.mkdtemp()
    proc = subprocess.Popen(
        [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--remote-debugging-port=0", "--window-size=1280,900", f"--user-data-dir={profile}",
         "about:blank"],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        with contextlib.ExitStack() as stack:
            check(stack, proc, robots, url, token, states, resume)
    finally:
        proc.kill()
        proc.wait()


def check(stack, proc, robots, url, token, states, resume):
    browser_ws = None
    for line in proc.stderr:
        m = re.search(r"ws://\S+", line)
        if m:
            browser_ws = m.group(0)
            break
    # Keep draining, so that Chromium never blocks on a full pipe.
    threading.Thread(target=lambda: [None for _ in proc.stderr], daemon=True).start()
    out = {}
    drawn = f"Object.keys(window.dashboard ? dashboard.drawn : {{}}).length >= {robots}"
    ro = Page(stack, browser_ws, url)
    ro.until(drawn)
    disabled = ro.eval("document.getElementById('stop').disabled")
    status = ro.eval("dashboard.order('stop')", wait=True)
    out["readonly"] = {"disabled": disabled, "status": status}
    samples = []
    for _ in range(20):
        d = ro.eval("JSON.stringify(dashboard.drawn)")
        for k, v in json.loads(d).items():
            samples.append([int(k), v["t"], v["world"][0], v["world"][1]])
        time.sleep(0.05)
    out["samples"] = samples
    out["table"] = ro.eval("[...document.querySelectorAll('#robots tbody tr')]"
                           ".filter((r) => r.style.display !== 'none')"
                           ".map((r) => [...r.cells].map((c) => c.textContent))")
    out["cells"] = [ro.eval(f"dashboard.cells({k}, {json.dumps(st)}, null, {age})")
                    for k, st, age in states]
    op = Page(stack, browser_ws, f"{url}?token={token}")
    op.until(drawn)
    op.until("!document.getElementById('stop').disabled")
    out["stop"] = press(op, "stop", 1)
    if resume:
        time.sleep(1.0)
        out["resume"] = press(op, "resume", 2)
    out["errors"] = ro.errors + op.errors
    print(json.dumps(out))


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("url")
    parser.add_argument("token")
    parser.add_argument("robots", type=int)
    parser.add_argument("--states", default="[]")
    parser.add_argument("--resume", action="store_true")
    a = parser.parse_args()
    main(a.url, a.token, a.robots, json.loads(a.states), a.resume)
