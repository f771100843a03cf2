#!/usr/bin/env python3
"""Open every page of the built guide in headless Chromium and fail on a broken one.

    python3 scripts/guide/open_pages.py docs/guide/book [--chromium chromium]

One browser is started for all pages and driven through the DevTools protocol over a pipe
(`--remote-debugging-pipe`: no network port). Each page is loaded from its file; a page fails
when a resource it asks for (image, style sheet, script, font) fails to load, when a script
throws, or when its rendered text is empty (`<main>` without visible text). Prints one line per
failure and a summary; exits 1 when any page failed, 2 when no browser could be started.
"""

import argparse
import fcntl
import json
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

PAGE_TIMEOUT_S = 30.0


class Browser:
    """Chromium driven by the DevTools protocol on fds 3 (commands in) and 4 (events out)."""

    def __init__(self, exe):
        self.profile = tempfile.mkdtemp(prefix="femu-guide-chromium-")
        to_browser_r, self.to_browser = os.pipe()
        self.from_browser, from_browser_w = os.pipe()

        def child_fds():
            # Out of the way first (fd 10 and up), so that neither lands on the other's target.
            a = fcntl.fcntl(to_browser_r, fcntl.F_DUPFD, 10)
            b = fcntl.fcntl(from_browser_w, fcntl.F_DUPFD, 10)
            os.dup2(a, 3)
            os.dup2(b, 4)

        self.proc = subprocess.Popen(
            [
                exe,
                "--headless",
                "--remote-debugging-pipe",
                "--no-sandbox",
                "--disable-gpu",
                "--no-first-run",
                "--no-default-browser-check",
                "--allow-file-access-from-files",
                f"--user-data-dir={self.profile}",
                "about:blank",
            ],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            preexec_fn=child_fds,
            close_fds=False,
        )
        os.close(to_browser_r)
        os.close(from_browser_w)
        self.buffer = b""
        self.next_id = 0
        self.events = []

    def send(self, method, params=None, session=None):
        self.next_id += 1
        msg = {"id": self.next_id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self.to_browser, json.dumps(msg).encode() + b"\0")
        return self.next_id

    def read_message(self, deadline):
        while b"\0" not in self.buffer:
            if time.monotonic() > deadline:
                raise TimeoutError("no answer from Chromium")
            import select

            ready, _, _ = select.select([self.from_browser], [], [], 0.5)
            if ready:
                chunk = os.read(self.from_browser, 1 << 20)
                if not chunk:
                    raise RuntimeError("Chromium closed its pipe")
                self.buffer += chunk
        raw, self.buffer = self.buffer.split(b"\0", 1)
        return json.loads(raw)

    def call(self, method, params=None, session=None, timeout=PAGE_TIMEOUT_S):
        wanted = self.send(method, params, session)
        deadline = time.monotonic() + timeout
        while True:
            msg = self.read_message(deadline)
            if msg.get("id") == wanted:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})
            self.events.append(msg)

    def wait_event(self, method, session, timeout=PAGE_TIMEOUT_S):
        deadline = time.monotonic() + timeout
        for i, msg in enumerate(self.events):
            if msg.get("method") == method and msg.get("sessionId") == session:
                del self.events[i]
                return msg
        while True:
            msg = self.read_message(deadline)
            if msg.get("method") == method and msg.get("sessionId") == session:
                return msg
            self.events.append(msg)

    def close(self):
        try:
            self.send("Browser.close")
            self.proc.wait(timeout=10)
        except Exception:
            self.proc.kill()
            self.proc.wait()
        shutil.rmtree(self.profile, ignore_errors=True)


def check_page(browser, path):
    """The problems of one page (an empty list when it is fine)."""
    target = browser.call("Target.createTarget", {"url": "about:blank"})["targetId"]
    session = browser.call("Target.attachToTarget", {"targetId": target, "flatten": True})[
        "sessionId"
    ]
    browser.events.clear()
    for domain in ("Page", "Network", "Runtime"):
        browser.call(f"{domain}.enable", session=session)
    browser.call("Page.navigate", {"url": path.as_uri()}, session=session)
    browser.wait_event("Page.loadEventFired", session)
    # Let late resources (fonts) settle.
    time.sleep(0.2)
    text = browser.call(
        "Runtime.evaluate",
        {
            "expression": "(document.querySelector('main') || document.body).innerText.trim().length",
            "returnByValue": True,
        },
        session=session,
    )["result"].get("value", 0)
    problems = []
    urls = {}
    for msg in browser.events:
        if msg.get("sessionId") != session:
            continue
        params = msg.get("params", {})
        if msg.get("method") == "Network.requestWillBeSent":
            urls[params["requestId"]] = params["request"]["url"]
        elif msg.get("method") == "Network.loadingFailed" and not params.get("canceled"):
            url = urls.get(params["requestId"], "?")
            problems.append(f"resource failed: {url} ({params.get('errorText')})")
        elif msg.get("method") == "Runtime.exceptionThrown":
            d = params.get("exceptionDetails", {})
            problems.append(f"script error: {d.get('exception', {}).get('description') or d.get('text')}")
    if not text:
        problems.append("empty page: no visible text")
    browser.call("Target.closeTarget", {"targetId": target})
    return problems


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("book", type=pathlib.Path, help="the built guide (docs/guide/book)")
    ap.add_argument("--chromium", default=shutil.which("chromium") or "chromium")
    args = ap.parse_args()
    pages = sorted(p for p in args.book.rglob("*.html") if p.name not in ("404.html",))
    if not pages:
        print(f"no HTML pages under {args.book}", file=sys.stderr)
        return 1
    try:
        browser = Browser(args.chromium)
        browser.call("Browser.getVersion", timeout=60)
    except Exception as e:  # no browser, or it would not start
        print(f"could not start Chromium ({args.chromium}): {e}", file=sys.stderr)
        return 2
    failed = 0
    try:
        for page in pages:
            problems = check_page(browser, page.resolve())
            for p in problems:
                print(f"{page.relative_to(args.book)}: {p}")
            failed += bool(problems)
    finally:
        browser.close()
    print(f"guide pages opened in Chromium: {len(pages)}, failed: {failed}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
