"""Faults from outside: SIGINT/SIGTERM/kill -9 in a stage, two runs at once, read-only and full
disks, a damaged compiled-code cache. Each ends as one line with the right exit code, nothing
half-written, and the next run resumes. The process that is signalled, killed or runs first is a
real child: the command line with fake stages (``fake_cli.py``), forked from this process with the
package already imported (a fresh interpreter imports it again, about 1.7 s of CPU per child; the
disk-full case starts ``fake_cli.py`` itself, the ``python -m pipeline`` start: test_cli.py); the run
after the fault is the same command line in this process. The tmpfs disk-full case needs root and
``mount`` (skipped otherwise)."""

from __future__ import annotations

import math
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
import traceback
from pathlib import Path

import casadi as ca
import pytest

from pipeline import cli
from pipeline.core import codegen, config
from pipeline.run import stages as stage_registry
from tests.reliability import fake_cli

REPO = Path(__file__).resolve().parents[2]

FAKE_CLI = Path(__file__).with_name("fake_cli.py")


class ForkedRun:
    """``fake_cli.py run --out <tmp>/runs *args`` in a child forked from this process: what
    ``fake_cli.py`` does as a script (:func:`pipeline.cli.main` with the fake stages), with the
    signal handlers of a fresh interpreter, its stderr in a file, its exit code as the process's.
    The parts of :class:`subprocess.Popen` the tests use: ``pid``, ``returncode``, ``poll``,
    ``send_signal``, ``kill`` and ``communicate`` (``(None, stderr text)``)."""

    def __init__(self, tmp_path: Path, *args: str) -> None:
        argv = ["run", "--out", str(tmp_path / "runs"), *args]
        self._stderr = tmp_path / f"child-{len(list(tmp_path.glob('child-*.err')))}.err"
        sys.stdout.flush()
        sys.stderr.flush()
        self.pid = os.fork()
        if self.pid == 0:          # the child: never returns into the test
            os._exit(self._child(tmp_path, argv))
        self.returncode: int | None = None

    def _child(self, cwd: Path, argv: list[str]) -> int:
        code = 1
        try:
            err = os.open(self._stderr, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
            os.dup2(err, 2)
            os.dup2(os.open(os.devnull, os.O_WRONLY), 1)
            sys.stdout, sys.stderr = open(1, "w", closefd=False), open(2, "w", closefd=False)  # noqa: SIM115
            signal.signal(signal.SIGINT, signal.default_int_handler)
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            os.chdir(cwd)
            stage_registry.STAGES = fake_cli.registry()
            config.robot_run_defaults = fake_cli.no_run_defaults
            code = cli.main(argv)
        except SystemExit as exc:  # argparse: its message is on stderr already
            code = exc.code if isinstance(exc.code, int) else 1
        except BaseException:      # noqa: BLE001 - reported on the child's stderr, as a script would
            traceback.print_exc()
        finally:
            sys.stderr.flush()
        return code

    def poll(self) -> int | None:
        if self.returncode is None:
            pid, status = os.waitpid(self.pid, os.WNOHANG)
            if pid:
                self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def send_signal(self, sig: int) -> None:
        os.kill(self.pid, sig)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)

    def wait(self, timeout: float) -> int:
        deadline = time.monotonic() + timeout
        while self.poll() is None:
            if time.monotonic() > deadline:
                self.kill()
                raise subprocess.TimeoutExpired(f"fork of {FAKE_CLI.name}", timeout)
            time.sleep(0.01)
        return self.returncode

    def communicate(self, timeout: float = 60.0) -> tuple[None, str]:
        self.wait(timeout)
        return None, self._stderr.read_text(errors="replace")


def _start(tmp_path: Path, *args: str) -> ForkedRun:
    """``fake_cli.py run --out <tmp>/runs *args`` in a child process (:class:`ForkedRun`)."""
    return ForkedRun(tmp_path, *args)


@pytest.fixture
def resume(monkeypatch, capsys):
    """``resume(tmp_path, *args) -> (exit code, stderr)``: the same fake command line in this process
    (:func:`pipeline.cli.main` with :func:`fake_cli.registry`), for the run after the fault: what it
    reuses and commits is read from the run directory, not from the process that made it."""
    monkeypatch.setattr(stage_registry, "STAGES", fake_cli.registry())
    monkeypatch.setattr(config, "robot_run_defaults", fake_cli.no_run_defaults)

    def call(tmp_path: Path, *args: str) -> tuple[int, str]:
        capsys.readouterr()
        code = cli.main(["run", "--out", str(tmp_path / "runs"), *args])
        return code, capsys.readouterr().err

    return call


def _wait_for(path: Path, proc: ForkedRun, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not path.exists():
        if proc.poll() is not None or time.monotonic() > deadline:
            out, err = proc.communicate()
            pytest.fail(f"stage did not start: rc={proc.returncode} {err}")
        time.sleep(0.05)


def _committed(run_dir: Path) -> set[str]:
    return {p.name for p in run_dir.iterdir() if (p / "inputs.sha256").exists()}


def _leftovers(run_dir: Path) -> list[str]:
    return [p.name for p in run_dir.iterdir() if ".partial-" in p.name or ".old-" in p.name]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_in_a_stage_exits_130_and_commits_nothing(tmp_path, sig, resume):
    proc = _start(tmp_path, "--set", "name=r", "--set", "b.sleep_s=60")
    run_dir = tmp_path / "runs" / "r"
    _wait_for(run_dir / "b.started", proc)
    t0 = time.monotonic()
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=30)
    assert time.monotonic() - t0 < 10
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1].startswith("interrupted")
    assert "Traceback" not in err
    assert _committed(run_dir) == {"a"} and not _leftovers(run_dir)
    code, err = resume(tmp_path, "--set", "name=r")
    assert code == 0, err
    assert "a: reused" in err and _committed(run_dir) == {"a", "b", "c"}


def test_concurrent_run_is_refused_naming_the_pid_and_kill_9_leaves_no_half_stage(tmp_path, resume):
    """A second run while another process works on the run directory is refused, naming that
    process; kill -9 of the first then leaves no half stage, and its lock dies with it."""
    first = _start(tmp_path, "--set", "name=r", "--set", "b.sleep_s=60")
    run_dir = tmp_path / "runs" / "r"
    _wait_for(run_dir / "b.started", first)
    code, err = resume(tmp_path, "--set", "name=r", "--set", "seed=2")
    assert code == 2
    assert err.strip().splitlines() == [f"error: {run_dir}: process {first.pid} is running on this run "
                                        "directory; wait for it to finish or choose another name/--out"]
    first.kill()
    first.communicate(timeout=30)
    assert _committed(run_dir) == {"a"}                     # the staging dir is not a stage
    code, err = resume(tmp_path, "--set", "name=r")
    assert code == 0, err
    assert _committed(run_dir) == {"a", "b", "c"} and not _leftovers(run_dir)


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores directory permissions")
def test_read_only_run_dir_reuses_when_nothing_to_write(tmp_path):
    done = _start(tmp_path, "--set", "name=r")
    assert done.wait(timeout=60) == 0
    run_dir = tmp_path / "runs" / "r"
    run_dir.chmod(0o555)
    try:
        again = _start(tmp_path, "--set", "name=r")
        _, err = again.communicate(timeout=60)
        assert again.returncode == 0 and "read-only: every stage reused" in err
        changed = _start(tmp_path, "--set", "name=r", "--set", "seed=3")
        _, err = changed.communicate(timeout=60)
        assert changed.returncode == 2 and err.strip().splitlines()[-1].startswith("error: ")
    finally:
        run_dir.chmod(0o755)


def _tmpfs(path: Path, size: str) -> bool:
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    path.mkdir()
    return subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                          capture_output=True, check=False).returncode == 0


@pytest.mark.slow
def test_disk_full_is_one_line_and_keeps_older_artefacts(tmp_path):
    disk = tmp_path / "disk"
    if not _tmpfs(disk, "1m"):
        pytest.skip("needs root and a working tmpfs mount")
    try:
        out = disk / "runs"
        env = {**os.environ, "PYTHONPATH": str(REPO)}
        sizes = [item for stage in "abc" for item in ("--set", f"{stage}.values_per_seed_squared=20000")]
        small = subprocess.run([sys.executable, str(FAKE_CLI), "run", "--out", str(out), "--set", "name=r",
                                "--set", "seed=1", *sizes], capture_output=True, text=True, env=env, check=False)
        assert small.returncode == 0, small.stderr
        before = (out / "r" / "a" / "results.npz").read_bytes()
        big = subprocess.run([sys.executable, str(FAKE_CLI), "run", "--out", str(out), "--set", "name=r",
                              "--set", "seed=3", *sizes], capture_output=True, text=True, env=env, check=False)
        assert big.returncode == 2 and "No space left on device" in big.stderr.strip().splitlines()[-1]
        assert "Traceback" not in big.stderr
        assert (out / "r" / "a" / "results.npz").read_bytes() == before
    finally:
        subprocess.run(["umount", str(disk)], check=False)


# ------------------------------------------------------------------------------ compiled code cache
def _tiny_function():
    x = ca.SX.sym("x", 2)
    return ca.Function("tiny_fault_test", [x], [ca.sin(x) * 2.0])


def test_truncated_library_is_rebuilt(tmp_path):
    library = codegen.build_library("tiny", [_tiny_function()], cache_dir=tmp_path)
    data = library.read_bytes()
    library.write_bytes(data[: len(data) // 3])                 # dlopen of this would SIGBUS
    again = codegen.build_library("tiny", [_tiny_function()], cache_dir=tmp_path)
    assert again == library and library.read_bytes() == data
    value = float(codegen.compile_function(_tiny_function(), cache_dir=tmp_path)([1.0, 2.0])[0])
    assert value == pytest.approx(2.0 * math.sin(1.0))


def test_cache_honours_xdg_and_falls_back_when_unwritable(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("PIPELINE_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert codegen.cache_root() == tmp_path / "xdg" / "pipeline"
    blocker = tmp_path / "not_a_dir"
    blocker.write_text("a file where the cache folder should be")
    monkeypatch.setattr(codegen, "_FALLBACK", [])
    library = codegen.build_library("tiny", [_tiny_function()], cache_dir=blocker / "cache")
    assert library.exists() and not library.is_relative_to(blocker)
    assert "not writable" in capsys.readouterr().err


IPOPT_SCRIPT = textwrap.dedent('''
    import sys
    import casadi as ca
    from pipeline.core.interrupts import handle_termination, raise_if_interrupted
    n = 2000
    x = ca.MX.sym("x", n)
    f = ca.sum1(100 * (x[1:] - x[:-1] ** 2) ** 2 + (1 - x[:-1]) ** 2) + ca.sum1(ca.sin(x) ** 4)
    solver = ca.nlpsol("s", "ipopt", {"x": x, "f": f}, {"ipopt.max_iter": 100000, "ipopt.print_level": 0,
                       "print_time": 0, "ipopt.tol": 1e-30, "ipopt.hessian_approximation": "limited-memory"})
    print("ready", flush=True)
    try:
        with handle_termination():
            solver(x0=[-1.2] * n)
            raise_if_interrupted(solver.stats())
    except KeyboardInterrupt as exc:
        print("interrupted:", exc, flush=True)
        sys.exit(130)
    print("finished:", solver.stats()["return_status"], flush=True)
''')


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_inside_ipopt_becomes_an_interrupt(tmp_path, sig):
    script = tmp_path / "ipopt.py"
    script.write_text(IPOPT_SCRIPT)
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert proc.stdout.readline().strip() == "ready"
    time.sleep(1.0)
    t0 = time.monotonic()
    proc.send_signal(sig)
    out, _ = proc.communicate(timeout=30)
    assert time.monotonic() - t0 < 10
    assert proc.returncode == 130 and "interrupted: solver stopped: NonIpopt_Exception_Thrown" in out
