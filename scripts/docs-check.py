#!/usr/bin/env python3
"""Run the commands the docs show, as written, from the repository root.

Every fenced ```sh, ```bash, ```shell and ```console block of README.md and
docs/**/*.md is run with bash (-e -u -o pipefail), in the order of the page,
with target/release (the `navsync` binary of `cargo build --release`) first
on PATH. A block fails when a command exits non-zero or exceeds its time.

Markers, HTML comments on the lines just above a block (visible in the
markdown source, invisible on the rendered page):

  <!-- docs-check: skip: REASON -->      not run; listed with REASON
  <!-- docs-check: needs: PATH -->       run only where PATH exists (shared
                                         data outside the repository), else
                                         listed as skipped
  <!-- docs-check: timeout: S -->        seconds allowed (default 120)
  <!-- docs-check: expect: A | B -->     the block's output contains A and B
  <!-- docs-check: expect FILE: A | B --> FILE, after the block, contains them
  <!-- docs-check: output -->            on a plain block: every line of it
                                         is in the output of the block run
                                         last (the figures a command prints)

In a ```console block, lines starting with `$ ` are the commands and the
other lines their expected output (each contained in it). Text is compared
with runs of white space collapsed. A page's ```python blocks run after its
shell blocks, in one interpreter (a block uses the names defined above it),
in a temporary directory, with the interpreter that imports the navsync
package ($NAVSYNC_PYTHON or target/venv/bin/python); without one they are
listed as skipped.

Afterwards the repository must hold no file it did not hold before (outside
target/): commands that write go to target/ or a temporary directory.

Usage (from anywhere): scripts/docs-check.py [--list] [FILE.md ...]
Exit status: 0 when every block that ran passed, 1 otherwise.
"""
import argparse
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SHELL_LANGS = {"sh", "bash", "shell", "console"}
FENCE = re.compile(r"^(\s*)(`{3,}|~{3,})\s*([\w+-]*)")
MARKER = re.compile(r"^\s*<!--\s*docs-check:\s*(.*?)\s*-->\s*$")
DEFAULT_TIMEOUT_S = 120


class Block:
    def __init__(self, path, line, lang, text, markers):
        self.path, self.line, self.lang, self.text = path, line, lang, text
        self.markers = markers  # list of (key, arg, value)
        self.where = f"{path.relative_to(ROOT)}:{line}"

    def marker(self, key):
        return [(arg, value) for k, arg, value in self.markers if k == key]


def parse_marker(text, where):
    """`key[ arg]: value` or a bare `key`."""
    head, sep, value = text.partition(":")
    key, _, arg = head.strip().partition(" ")
    if key not in {"skip", "needs", "timeout", "expect", "output"}:
        raise SystemExit(f"{where}: unknown docs-check marker '{text}'")
    if key != "output" and not sep:
        raise SystemExit(f"{where}: docs-check marker '{text}' needs ': VALUE'")
    return key, arg.strip(), value.strip()


def blocks_of(path):
    """The fenced blocks of a markdown file, with the markers above them."""
    lines = path.read_text(encoding="utf-8").splitlines()
    out, pending, i = [], [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            mk = MARKER.match(lines[i])
            if mk:
                pending.append(parse_marker(mk.group(1), f"{path}:{i + 1}"))
            elif lines[i].strip():
                pending = []  # markers belong to the block right below them
            i += 1
            continue
        fence, lang, start = m.group(2), m.group(3).lower(), i + 1
        body = []
        i += 1
        while i < len(lines) and not lines[i].strip().startswith(fence):
            body.append(lines[i][len(m.group(1)):] if lines[i].startswith(m.group(1)) else lines[i])
            i += 1
        if i >= len(lines):
            raise SystemExit(f"{path}:{start}: code block never closed")
        out.append(Block(path, start, lang, "\n".join(body) + "\n", pending))
        pending = []
        i += 1
    return out


def squash(s):
    return re.sub(r"\s+", " ", s).strip()


def missing(expected, text):
    """The expected snippets (white space collapsed) absent from text."""
    have = squash(text)
    return [e for e in expected if squash(e) and squash(e) not in have]


def console_split(text):
    """A console block's commands (`$ ` lines) and expected output lines."""
    cmds, expected = [], []
    for line in text.splitlines():
        if line.startswith("$ "):
            cmds.append(line[2:])
        elif line.strip():
            expected.append(line)
    return "\n".join(cmds) + "\n", expected


def repo_files():
    """Paths git sees in the working tree outside target/ (ignored too)."""
    r = subprocess.run(["git", "status", "--porcelain", "--ignored", "--untracked-files=all"],
                       cwd=ROOT, capture_output=True, text=True, check=True)
    paths = set()
    for line in r.stdout.splitlines():
        p = line[3:]
        if not (p.startswith("target/") or "/target/" in p or "__pycache__" in p):
            paths.add(p)
    return paths


def run(block, env):
    """Run one shell block; returns (ok, seconds, output, message)."""
    script, expected = block.text, []
    if block.lang == "console":
        script, expected = console_split(block.text)
    timeout_s = float(block.marker("timeout")[0][1]) if block.marker("timeout") else DEFAULT_TIMEOUT_S
    t0 = time.monotonic()
    # A session of its own, so that a timeout ends the block's children too.
    p = subprocess.Popen(["bash", "-euo", "pipefail", "-c", script], cwd=ROOT, env=env,
                         stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, start_new_session=True)
    try:
        raw, _ = p.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        raw, _ = p.communicate()
        out = raw.decode("utf-8", "replace")
        return False, time.monotonic() - t0, out, f"still running after {timeout_s:.0f} s"
    dt = time.monotonic() - t0
    out = raw.decode("utf-8", "replace")
    if p.returncode != 0:
        return False, dt, out, f"exit status {p.returncode}"
    for arg, value in block.marker("expect"):
        wanted = [v.strip() for v in value.split("|")]
        if arg:
            f = ROOT / arg if not os.path.isabs(arg) else Path(arg)
            if not f.is_file():
                return False, dt, out, f"expected file {arg} was not written"
            text = f.read_text(encoding="utf-8", errors="replace")
        else:
            text = out
        gone = missing(wanted, text)
        if gone:
            return False, dt, out, f"not found in {arg or 'the output'}: " + "; ".join(gone)
    gone = missing(expected, out)
    if gone:
        return False, dt, out, "console output lacks: " + "; ".join(gone)
    return True, dt, out, ""


# Guarded: worker processes that re-import the main module (Dask's
# LocalCluster spawns them) must not run the blocks again.
PY_DRIVER = r"""
import sys, json, traceback
if __name__ == "__main__":
    g = {"__name__": "__docs_check__"}
    for where, code in json.load(open(sys.argv[1])):
        try:
            exec(compile(code, where, "exec"), g)
        except BaseException:
            traceback.print_exc()
            print("@@fail " + where, flush=True)
            sys.exit(1)
        print("@@ok " + where, flush=True)
"""


def python_exe():
    """The interpreter with the navsync package: $NAVSYNC_PYTHON, else
    target/venv/bin/python (.ci/run makes it with CI=true), else None."""
    exe = os.environ.get("NAVSYNC_PYTHON") or str(ROOT / "target" / "venv" / "bin" / "python")
    if not os.path.isfile(exe):
        return None
    r = subprocess.run([exe, "-c", "import navsync"], capture_output=True)
    return exe if r.returncode == 0 else None


class Checker:
    def __init__(self, env, listing):
        self.env, self.listing = env, listing
        self.ran = self.failed = 0
        self.skipped = []
        self.last_out = None
        self.py = None if listing else python_exe()

    def fail(self, where, why, text, out):
        self.failed += 1
        print(f"FAIL {where}: {why}\n  block:")
        for line in text.rstrip().splitlines():
            print(f"    {line}")
        print("  last output:")
        for line in out.rstrip().splitlines()[-15:]:
            print(f"    {line}")

    def skip_reason(self, b):
        reason = b.marker("skip")[0][1] if b.marker("skip") else None
        for _, path in b.marker("needs"):
            if not (ROOT / path).exists():
                reason = reason or f"needs {path}, absent here"
        if b.lang == "python" and not reason and not self.listing and self.py is None:
            reason = "needs the navsync Python package (target/venv, which .ci/run makes with CI=true, or NAVSYNC_PYTHON)"
        return reason

    def output_block(self, b):
        if self.listing:
            print(f"     {b.where}: printed figures checked against the block run before it")
        elif self.last_out is None:
            self.fail(b.where, "an output block with no command run before it", b.text, "")
        else:
            gone = missing(b.text.splitlines(), self.last_out)
            if gone:
                self.fail(b.where, "the command above no longer prints: " + "; ".join(gone), b.text, "")
            else:
                print(f"ok   {b.where}: {len(b.text.strip().splitlines())} printed lines match")

    def shell_block(self, b, first):
        if self.listing:
            print(f"run  {b.where}: {first}")
            return
        ok, dt, out, why = run(b, self.env)
        self.ran += 1
        self.last_out = out
        if ok:
            print(f"ok   {b.where} ({dt:.1f} s): {first}")
        else:
            self.fail(f"{b.where} ({dt:.1f} s)", why, b.text, out)

    def python_blocks(self, blocks):
        """A page's Python blocks in one interpreter, in order (a block uses
        the names of those above it), in a temporary directory."""
        if not blocks:
            return
        if self.listing:
            for b in blocks:
                print(f"run  {b.where}: python")
            return
        import json
        import shutil
        import tempfile
        work = tempfile.mkdtemp(prefix="docs-check-py-")
        try:
            spec = Path(work) / "blocks.json"
            spec.write_text(json.dumps([(b.where, b.text) for b in blocks]))
            driver = Path(work) / "driver.py"
            driver.write_text(PY_DRIVER)
            t0 = time.monotonic()
            try:
                r = subprocess.run([self.py, str(driver), str(spec)], cwd=work, env=self.env,
                                   stdin=subprocess.DEVNULL, capture_output=True, text=True,
                                   timeout=DEFAULT_TIMEOUT_S * len(blocks))
                out, code = r.stdout + r.stderr, r.returncode
            except subprocess.TimeoutExpired as e:
                out, code = str(e.stdout or ""), -1
            dt = time.monotonic() - t0
        finally:
            shutil.rmtree(work, ignore_errors=True)
        done = {line[5:] for line in out.splitlines() if line.startswith("@@ok ")}
        for b in blocks:
            self.ran += 1
            if b.where in done:
                print(f"ok   {b.where} (python, {dt:.1f} s for the page): {b.text.splitlines()[0]}")
            else:
                self.fail(f"{b.where} (python)", "exception or exit " + str(code), b.text, out)
                self.ran += len(blocks) - blocks.index(b) - 1
                break

    def page(self, f):
        python = []
        for b in blocks_of(f):
            first = b.text.strip().splitlines()[0] if b.text.strip() else ""
            if b.marker("output"):
                self.output_block(b)
                continue
            if b.lang not in SHELL_LANGS | {"python"}:
                continue
            reason = self.skip_reason(b)
            if reason:
                self.skipped.append((b.where, first, reason))
                print(f"skip {b.where}: {reason}")
            elif b.lang == "python":
                python.append(b)
            else:
                self.shell_block(b, first)
        self.python_blocks(python)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--list", action="store_true", help="list the blocks and markers, run nothing")
    ap.add_argument("files", nargs="*", type=Path)
    a = ap.parse_args()
    files = [f.resolve() for f in a.files] or [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))
    bin_dir = ROOT / "target" / "release"
    env = dict(os.environ, PATH=f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}")
    if not a.list and not (bin_dir / "navsync").is_file():
        sys.exit(f"{bin_dir / 'navsync'} not found: run `cargo build --release` first")
    before = set() if a.list else repo_files()
    c = Checker(env, a.list)
    t_all = time.monotonic()
    for f in files:
        c.page(f)
    if a.list:
        return 0
    left = sorted(repo_files() - before)
    if left:
        c.failed += 1
        print("FAIL the docs' commands left files in the repository (write to target/ or /tmp):")
        for p in left:
            print(f"    {p}")
    print(f"\ndocs-check: {c.ran} blocks run, {c.failed} failed, {len(c.skipped)} skipped, "
          f"{time.monotonic() - t_all:.0f} s")
    for where, first, reason in c.skipped:
        print(f"  skipped {where}: {reason}  [{first}]")
    return 1 if c.failed else 0


if __name__ == "__main__":
    sys.exit(main())
