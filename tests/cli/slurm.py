"""A single-node Slurm cluster on this machine, for tests: munged, slurmctld and slurmd with a
slurm.conf in a temporary folder, started as root and stopped afterwards."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["INSTALL", "slurm_cluster"]

INSTALL = "apt-get install -y slurm-wlm munge"
_BINARIES = ("munged", "slurmctld", "slurmd", "sbatch", "squeue", "sinfo", "scancel")

# Without accounting, sacct fails, and submitit then waits forever on a job that died before
# writing its result; this stand-in answers submitit's query from squeue.
_SACCT = """#!/bin/sh
echo 'JobID|State|NodeList'
exec squeue -h -t all -o '%i|%T|%N'
"""


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _free_memory_mb() -> int:
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith("MemAvailable:"):
            return int(line.split()[1]) // 1024
    return 4096


def _stop(pid_file: Path, timeout: float = 15.0) -> None:
    """SIGTERM the daemon named in ``pid_file`` and wait until it has exited."""
    try:
        pid = int(pid_file.read_text().split()[0])
        os.kill(pid, signal.SIGTERM)
    except (FileNotFoundError, ProcessLookupError, ValueError, IndexError):
        return
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.1)


def missing_binaries() -> list[str]:
    return [name for name in _BINARIES if shutil.which(name) is None and not Path("/usr/sbin", name).exists()]


@contextmanager
def slurm_cluster(folder: Path, timeout: float = 60.0) -> Iterator[dict[str, str]]:
    """Start a one-node cluster; yields the environment (SLURM_CONF, PATH) that reaches it."""
    folder.mkdir(parents=True, exist_ok=True)
    host = socket.gethostname()
    for sub in ("state", "spool", "bin"):
        (folder / sub).mkdir(exist_ok=True)
    munge_run = Path("/run/munge")
    munge_run.mkdir(parents=True, exist_ok=True)
    shutil.chown(munge_run, "munge", "munge")
    munge_pid = munge_run / "munged.pid"
    conf = folder / "slurm.conf"
    conf.write_text(f"""ClusterName=kadvtest
SlurmctldHost={host}(127.0.0.1)
SlurmctldPort={_free_port()}
SlurmdPort={_free_port()}
AuthType=auth/munge
SlurmUser=root
SlurmdUser=root
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
MinJobAge=86400
ReturnToService=2
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
StateSaveLocation={folder / "state"}
SlurmdSpoolDir={folder / "spool"}
SlurmctldPidFile={folder / "slurmctld.pid"}
SlurmdPidFile={folder / "slurmd.pid"}
SlurmctldLogFile={folder / "slurmctld.log"}
SlurmdLogFile={folder / "slurmd.log"}
NodeName={host} NodeAddr=127.0.0.1 CPUs={os.cpu_count()} RealMemory={max(1024, _free_memory_mb() - 2048)} State=UNKNOWN
PartitionName=debug Nodes={host} Default=YES MaxTime=INFINITE State=UP
""")
    sacct = folder / "bin" / "sacct"
    sacct.write_text(_SACCT)
    sacct.chmod(0o755)
    env = {**os.environ, "SLURM_CONF": str(conf), "PATH": f"{folder / 'bin'}:{os.environ['PATH']}"}
    try:
        subprocess.run(["runuser", "-u", "munge", "--", "munged", "--force"], check=True, timeout=30)
        subprocess.run(["slurmctld", "-f", str(conf)], check=True, env=env, timeout=30)
        subprocess.run(["slurmd", "-f", str(conf)], check=True, env=env, timeout=30)
        deadline = time.monotonic() + timeout
        while True:
            state = subprocess.run(["sinfo", "-h", "-N", "-o", "%t"], capture_output=True, text=True, env=env).stdout
            if state.strip() == "idle":
                break
            if time.monotonic() > deadline:
                logs = "".join(p.read_text()[-2000:] for p in folder.glob("*.log"))
                raise RuntimeError(f"slurm node not idle after {timeout} s (sinfo: {state.strip()!r})\n{logs}")
            time.sleep(0.2)
        yield env
    finally:
        _stop(folder / "slurmd.pid")
        _stop(folder / "slurmctld.pid")
        _stop(munge_pid)
