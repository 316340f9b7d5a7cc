"""Every command and code block of README.md and docs/*.md runs as written.

A page's fenced blocks run in the page's order, in one scratch directory per page (under
``tmp_path``), as a reader would run them one after the other in a new directory:

- ```` ```python ````: ``exec`` in a fresh namespace, the scratch directory as working directory.
- ```` ```sh ````: ``bash -e -o pipefail``, with no traceback in its output, in the scratch
  directory, which holds ``.venv`` (a symbolic link to the prefix of the interpreter running the
  tests, ``sys.prefix``: the virtual environment the README's install command makes) and copies
  of ``studies/`` and ``examples/``. ``PATH`` is that of a fresh shell, without the
  environment's ``bin``: a block must say ``.venv/bin/cvxdual``, or ``source
  .venv/bin/activate`` before a plain ``cvxdual``, as the reader must. The block runs in its own
  process group, which is killed when the block ends (background commands such as ``dask
  scheduler ... &``).
- The two install commands of the Quick start cannot run here: they would rebuild the
  environment running the tests. Their ``python3 -m venv .venv && .venv/bin/pip install``
  prefix must be the one ``.ci/run`` uses and they must install this repository (``.`` or
  ``".[test]"``); the test command must be in ``.ci/run`` verbatim (CI runs it: lint and this
  suite). The rest of the main job's line (``.venv/bin/cvxdual solve``) runs as written. Any other
  ``pip install`` or ``python3 -m venv`` in a block that runs is refused.
- Blocks fenced ``toml`` or ``text`` are shown, not run; every ``toml`` block must parse, and one
  that is a whole scene (two bodies, or ``base``) is loaded with :func:`cvxdual.load_scene`, one that
  is a study spec (``scenes``) with :func:`cvxdual.study.load_spec`.
- A block preceded by ``<!-- docs-test: skip REASON -->`` is not run and is reported as skipped
  with its reason (commands of features that are not merged yet).

Nothing is written into the repository: the test fails if a file that a block wrote in its
scratch directory also appeared (or changed) at the same place in the repository while it ran.
"""

from __future__ import annotations

import logging
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = ["README.md", *sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").glob("*.md"))]
COPIED = ("studies", "examples")  # repository directories the blocks refer to, copied into each scratch dir
RUN = {"sh", "python"}
SHOWN = {"toml", "text"}
BLOCK_TIMEOUT = 300  # seconds; the whole set runs in about a minute
FENCE = re.compile(r"^(?P<indent>[ \t]*)```(?P<lang>[^\n`]*)\n(?P<body>.*?)^(?P=indent)```[ \t]*$", re.M | re.S)
SKIP = re.compile(r"<!--\s*docs-test:\s*skip\s+(?P<reason>[^<>]*?)\s*-->\s*\Z")  # right before the fence
INSTALL_PREFIX = "python3 -m venv .venv && .venv/bin/pip install "
INSTALL = re.compile(r"^python3 -m venv \.venv && \.venv/bin/pip install (?P<spec>\S+) && (?P<rest>.+)$")
THIS_REPO = {".", '".[test]"'}
TIMES: dict[str, float] = {}  # block -> seconds, printed at the end


@dataclass(frozen=True)
class Block:
    page: str
    line: int  # of the opening fence, 1-based
    lang: str
    code: str
    skip: str | None  # the reason, for blocks marked not to run

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line}"


def blocks(page: str) -> list[Block]:
    text = (ROOT / page).read_text(encoding="utf-8")
    out = []
    for m in FENCE.finditer(text):
        indent = m.group("indent")
        body = "".join(line[len(indent):] if line.startswith(indent) else line
                       for line in m.group("body").splitlines(keepends=True))
        skip = SKIP.search(text[:m.start()])
        out.append(Block(page, text.count("\n", 0, m.start()) + 1, m.group("lang").strip(), body,
                         skip.group("reason") if skip else None))
    return out


def ci_script() -> str:
    return (ROOT / ".ci" / "run").read_text()


# -- the README's install and test commands ----------------------------------------------------

def test_ci_runs_the_readme_test_command():
    readme = [b.code.strip() for b in blocks("README.md") if b.lang == "sh"]
    test_cmd = next(b for b in readme if "pytest" in b)
    assert test_cmd in ci_script()


def test_readme_install_commands_are_the_ones_ci_uses():
    lines = [line for b in blocks("README.md") if b.lang == "sh" for line in b.code.splitlines()
             if "pip install" in line]
    assert len(lines) == 2, "the Quick start has two install commands: the main job and the tests"
    assert lines[0] == "python3 -m venv .venv && .venv/bin/pip install . && .venv/bin/cvxdual solve"
    assert lines[1] in ci_script()
    assert INSTALL_PREFIX in ci_script()


def rewrite_installs(block: Block) -> str:
    """The block with its install commands checked and replaced by what runs after them."""
    lines = []
    for line in block.code.splitlines():
        m = INSTALL.match(line.strip())
        if m:
            assert INSTALL_PREFIX in ci_script(), f"{block.where}: .ci/run installs differently: {line}"
            assert m.group("spec") in THIS_REPO, f"{block.where}: installs {m.group('spec')}, not this repository"
            if "pytest" in line:  # the test command: lint and this suite, which .ci/run runs
                assert line.strip() in ci_script(), f"{block.where}: the test command is not in .ci/run verbatim"
                line = ":"
            else:
                line = m.group("rest")
        elif re.search(r"\bpip install\b|\bpython3? -m venv\b|\bvirtualenv\b", line):
            pytest.fail(f"{block.where}: {line.strip()!r} would change the environment running the tests; "
                        "show it in a ```text block")
        lines.append(line)
    return "\n".join(lines) + "\n"


# -- the fences ---------------------------------------------------------------------------------

def test_every_fence_names_a_known_language():
    bad = [f"{b.where} ```{b.lang}" for p in PAGES for b in blocks(p) if b.lang not in RUN | SHOWN]
    assert not bad, f"fence blocks need one of {sorted(RUN | SHOWN)}: {bad}"


def test_pages_are_linked_from_the_readme_and_links_resolve():
    readme = (ROOT / "README.md").read_text()
    for page in PAGES[1:]:
        assert f"]({page})" in readme, f"the README does not link {page}"
    missing = []
    for page in PAGES:
        text = FENCE.sub("", (ROOT / page).read_text())
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if re.match(r"[a-z]+:", target) or not re.search(r"/|\.\w+$", target.split("#")[0]):
                continue  # a URL, an anchor, or formula text such as [u](x)
            if not ((ROOT / page).parent / target.split("#")[0]).exists():
                missing.append(f"{page}: {target}")
    assert not missing, f"links to files that do not exist: {missing}"


# -- running the pages --------------------------------------------------------------------------

def fresh_env() -> dict:
    """The environment of a new shell: no virtual environment on PATH."""
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHONHOME", "CONDA_PREFIX")}
    venv_bins = {os.path.realpath(os.path.join(p, "bin")) for p in (sys.prefix, os.environ.get("VIRTUAL_ENV", ""))
                 if p}
    path = [p for p in env.get("PATH", os.defpath).split(os.pathsep)
            if p and os.path.realpath(p) not in venv_bins and not os.path.exists(os.path.join(p, "cvxdual"))]
    env["PATH"] = os.pathsep.join(path)
    env["MPLBACKEND"] = "Agg"
    return env


def kill_group(pgid: int) -> None:
    """End every process of the group (a block's background commands), politely first."""
    for sig, wait in ((signal.SIGTERM, 5.0), (signal.SIGKILL, 0.0)):
        try:
            os.killpg(pgid, sig)
        except ProcessLookupError:
            return
        deadline = time.monotonic() + wait
        while time.monotonic() < deadline:
            try:
                os.killpg(pgid, 0)
            except ProcessLookupError:
                return
            time.sleep(0.1)


def run_sh(block: Block, work: Path, logs: Path) -> None:
    script = logs / f"block-{block.line}.sh"
    script.write_text(rewrite_installs(block))
    log = logs / f"block-{block.line}.log"
    with open(log, "wb") as out:
        proc = subprocess.Popen(["bash", "-e", "-o", "pipefail", str(script)], cwd=work, env=fresh_env(),
                                stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            rc = proc.wait(BLOCK_TIMEOUT)
        except subprocess.TimeoutExpired:
            rc = None
        finally:
            kill_group(proc.pid)
            proc.wait()
    text = log.read_text(errors="replace")
    # a command shown failing on purpose (`... || echo ...`) must fail with its one line, not crash
    crashed = "Traceback (most recent call last)" in text
    if rc != 0 or crashed:
        why = ("printed a traceback" if crashed else f"timed out after {BLOCK_TIMEOUT} s" if rc is None
               else f"exited with status {rc}")
        pytest.fail(f"{block.where}: the sh block {why}:\n{block.code}\n--- output (end) ---\n{text[-4000:]}")


def run_python(block: Block, work: Path) -> None:
    code = compile("\n" * block.line + block.code, block.page, "exec")  # tracebacks give the page's lines
    cwd = os.getcwd()
    loggers = [logging.getLogger(), logging.getLogger("cvxdual")]
    saved = [(lg, lg.level, lg.handlers[:]) for lg in loggers]  # a block may configure logging
    os.chdir(work)
    try:
        exec(code, {"__name__": "__docs__"})
    finally:
        os.chdir(cwd)
        for lg, level, handlers in saved:
            lg.setLevel(level)
            lg.handlers[:] = handlers


def check_toml(block: Block, work: Path) -> None:
    try:
        data = tomllib.loads(block.code)
    except tomllib.TOMLDecodeError as e:
        pytest.fail(f"{block.where}: the toml block does not parse: {e}")
    cwd = os.getcwd()
    os.chdir(work)  # relative paths of a spec resolve here, as for a file written in the scratch directory
    try:
        if "base" in data or len(data.get("bodies", {})) == 2:  # a whole scene, not a snippet
            import cvxdual
            cvxdual.load_scene(data)
        elif "scenes" in data:
            from cvxdual.study import load_spec
            load_spec(data)
    finally:
        os.chdir(cwd)


def scratch(tmp_path: Path) -> tuple[Path, Path, set[str]]:
    """The page's scratch directory (with ``.venv`` and the copies) and a directory for the logs."""
    work, logs = tmp_path / "work", tmp_path / "logs"
    logs.mkdir()
    work.mkdir()
    (work / ".venv").symlink_to(sys.prefix, target_is_directory=True)
    for d in COPIED:
        shutil.copytree(ROOT / d, work / d, ignore=shutil.ignore_patterns("__pycache__"))
    copied = {p.relative_to(work).as_posix() for d in COPIED for p in (work / d).rglob("*")}
    return work, logs, copied


def written_into_repo(work: Path, copied: set[str], since: float) -> list[str]:
    """Files a block wrote in ``work`` that appeared or changed at the same place in the repository."""
    bad = []
    for dirpath, dirnames, filenames in os.walk(work):
        dirnames[:] = [d for d in dirnames if d != ".venv"]
        for f in filenames:
            rel = Path(dirpath, f).relative_to(work).as_posix()
            twin = ROOT / rel
            if rel not in copied and twin.exists() and twin.stat().st_mtime >= since - 1.0:
                bad.append(rel)
    return sorted(bad)


@pytest.mark.slow
@pytest.mark.skipif(not (Path(sys.prefix) / "bin" / "activate").is_file(),
                    reason="the tests do not run in a virtual environment (no bin/activate in sys.prefix)")
@pytest.mark.parametrize("page", PAGES)
def test_page_runs_as_written(page, tmp_path):
    work, logs, copied = scratch(tmp_path)
    since = time.time()
    for block in blocks(page):
        if block.skip is not None:
            continue
        t0 = time.perf_counter()
        if block.lang == "sh":
            run_sh(block, work, logs)
        elif block.lang == "python":
            run_python(block, work)
        elif block.lang == "toml":
            check_toml(block, work)
        TIMES[block.where] = time.perf_counter() - t0
    bad = written_into_repo(work, copied, since)
    assert not bad, f"{page}: blocks wrote into the repository: {bad}"


def test_blocks_marked_not_to_run():
    """Blocks marked ``<!-- docs-test: skip REASON -->`` (features not merged yet) are reported
    here as a skip with their reasons, so that they are enabled once their feature exists."""
    marked = [b for p in PAGES for b in blocks(p) if b.skip is not None]
    for b in marked:
        assert b.lang in RUN, f"{b.where}: only sh and python blocks run; drop the marker"
    if marked:
        pytest.skip("not run: " + "; ".join(f"{b.where} ({b.skip})" for b in marked))


def test_zz_report_times():
    """Not a check: the time each block took (shown with ``pytest -s``)."""
    if TIMES:
        width = max(map(len, TIMES))
        for where, t in sorted(TIMES.items(), key=lambda kv: -kv[1]):
            print(f"{where:{width}s} {t:7.2f} s")
        print(f"{'total':{width}s} {sum(TIMES.values()):7.2f} s")
