"""Runs the external tools (COLMAP, cashash) one at a time, niced, and times them.

The evaluation shares a small machine, so every heavy command goes through
run_tool: it is niced, runs alone, and its output goes to a log file that the
report can point to when something fails.
"""
import os
import resource
import shutil
import subprocess
import time


def _children_cpu_seconds():
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_tool(command, log_path, nice=10):
    """Runs command (list), appends its output to log_path.

    Returns (wall seconds, CPU seconds, stdout+stderr text). Raises
    RuntimeError with the log's tail when the command fails.
    """
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    full = (["nice", "-n", str(nice)] if nice else []) + [str(c) for c in command]
    cpu_before = _children_cpu_seconds()
    start = time.perf_counter()
    proc = subprocess.run(full, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    wall = time.perf_counter() - start
    cpu = _children_cpu_seconds() - cpu_before
    os.makedirs(os.path.dirname(log_path), exist_ok=True)
    with open(log_path, "a") as log:
        log.write("$ " + " ".join(full) + "\n" + proc.stdout + "\n")
    if proc.returncode != 0:
        tail = "\n".join(proc.stdout.splitlines()[-15:])
        raise RuntimeError("command failed (%d): %s\n%s" % (proc.returncode, " ".join(full), tail))
    return wall, cpu, proc.stdout


def copy_database(source, target):
    """Copies a COLMAP database (and a WAL file if one exists); never touches the source."""
    for suffix in ("-wal", "-shm"):
        if os.path.exists(target + suffix):
            os.remove(target + suffix)
    shutil.copyfile(source, target)
    if os.path.exists(source + "-wal"):
        shutil.copyfile(source + "-wal", target + "-wal")


def gpu_present():
    """True when nvidia-smi lists at least one GPU on this machine."""
    if shutil.which("nvidia-smi") is None:
        return False
    proc = subprocess.run(["nvidia-smi", "-L"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    return proc.returncode == 0 and "GPU" in proc.stdout
