#!/usr/bin/env python3
"""Checks the include rules of docs/ARCHITECTURE.md ("Who may use whom")
against the #include lines of the sources. Prints every violation and exits
1 on any. The known exceptions of the document are listed below by file and
header; a new exception must be added here and to the document alike.

Usage: include_rules.py [REPO]   (default: the repository of this script)
"""

import pathlib
import re
import sys

REPO = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else pathlib.Path(__file__).resolve().parents[2])

# Folders of src/cashash/ from the bottom up: a file may include its own
# folder and the folders below it (retrieval/ on top: it may use matching/
# and pipeline/, which never include it).
CORE_ORDER = ["base", "geometry", "matching", "matchers", "pipeline", "retrieval"]

# docs/ARCHITECTURE.md, "Known exceptions to this order": (file, header).
KNOWN_EXCEPTIONS = {
    ("src/cashash/matching/guided_matching.h", "cashash/matchers/exact_matcher.h"),
    ("src/cashash/matching/pair_matching.h", "cashash/matchers/feature_matcher.h"),
    ("src/cashash/matching/pair_matching.cc", "cashash/matchers/exact_matcher.h"),
    ("src/cashash/matching/guided_matching.cc", "cashash/pipeline/batch_verifier.h"),
}

# Only the bottom-most algorithms: cascade_matcher.h and brute_force_matcher.h
# include only base/ (and their own folder's option and hashing headers).
BASE_ONLY = ["src/cashash/matching/cascade_matcher.h", "src/cashash/matching/brute_force_matcher.h"]

SOURCE_SUFFIXES = {".h", ".cc", ".cu", ".cuh"}
INCLUDE = re.compile(r'^\s*#\s*include\s*([<"])([^">]+)[">]')


def includes(path):
    """(line number, kind, header, inside #ifdef CASHASH_WITH_CUDA) of each #include."""
    result = []
    stack = []  # one bool per open #if: whether it is CASHASH_WITH_CUDA
    for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
        stripped = line.strip()
        if re.match(r"#\s*if", stripped):
            stack.append(re.match(r"#\s*(ifdef\s+CASHASH_WITH_CUDA|if\s+defined\(CASHASH_WITH_CUDA\))", stripped)
                         is not None)
        elif re.match(r"#\s*endif", stripped) and stack:
            stack.pop()
        match = INCLUDE.match(line)
        if match:
            result.append((number, match.group(1), match.group(2), any(stack)))
    return result


def sources(folder):
    root = REPO / folder
    return sorted(p for p in root.rglob("*") if p.suffix in SOURCE_SUFFIXES) if root.exists() else []


def main():
    problems = []
    used_exceptions = set()

    def fail(path, number, text):
        problems.append(f"{path.relative_to(REPO)}:{number}: {text}")

    # cashash_core: only src/cashash/, the standard library and Eigen; and the
    # order of its folders.
    for path in sources("src/cashash"):
        rel = str(path.relative_to(REPO))
        folder = path.relative_to(REPO / "src/cashash").parts[0]
        for number, kind, header, _ in includes(path):
            if kind == '"':
                if not header.startswith("cashash/"):
                    fail(path, number, f'cashash_core includes "{header}" from outside src/cashash/')
                    continue
                target = header.split("/")[1]
                if target not in CORE_ORDER:
                    fail(path, number, f'unknown folder of "{header}"')
                    continue
                if CORE_ORDER.index(target) > CORE_ORDER.index(folder):
                    if (rel, header) in KNOWN_EXCEPTIONS:
                        used_exceptions.add((rel, header))
                    else:
                        fail(path, number, f"{folder}/ includes {header}, a folder above it")
                if folder == "geometry" and target not in ("base", "geometry"):
                    fail(path, number, f"geometry/ includes {header} (only base/)")
                if rel in BASE_ONLY and target not in ("base", "matching"):
                    fail(path, number, f"{path.name} includes {header} (only base/)")
                if rel in BASE_ONLY and target == "matching" and not header.endswith(
                        ("matching_options.h", "cascade_hashing.h")):
                    fail(path, number, f"{path.name} includes {header} (only base/)")
            elif not (header.startswith("Eigen/") or re.fullmatch(r"[a-z_0-9]+(\.h)?", header)):
                fail(path, number, f"cashash_core includes <{header}> (the standard library and Eigen only)")
            elif header in ("sqlite3.h", "mpi.h") or header.startswith(("cuda", "boost/")):
                fail(path, number, f"cashash_core includes <{header}>")

    # cashash_cuda: only cashash/ and cashash_cuda/; it knows no database.
    for path in sources("cuda"):
        for number, kind, header, _ in includes(path):
            if kind == '"' and not header.startswith(("cashash/", "cashash_cuda/")):
                fail(path, number, f'cashash_cuda includes "{header}" (only cashash/ and cashash_cuda/)')
            if kind == "<" and header in ("sqlite3.h", "mpi.h"):
                fail(path, number, f"cashash_cuda includes <{header}>")

    # cashash_distributed: only cashash/ and distributed/; <mpi.h> only in
    # mpi_process_group.cc.
    for path in sources("distributed"):
        for number, kind, header, _ in includes(path):
            if kind == '"' and not header.startswith(("cashash/", "distributed/")):
                fail(path, number, f'cashash_distributed includes "{header}" (only cashash/ and distributed/)')
    for folder in ("src", "cuda", "distributed", "colmap_bridge", "python", "synthetic", "app"):
        for path in sources(folder):
            for number, kind, header, _ in includes(path):
                if header == "mpi.h" and path.relative_to(REPO).as_posix() != "distributed/mpi_process_group.cc":
                    fail(path, number, "<mpi.h> outside distributed/mpi_process_group.cc")

    # cashash_bridge: the CUDA backend only under #ifdef CASHASH_WITH_CUDA;
    # never commands/ or synthetic/ (the commands may include the bridge).
    for path in sources("colmap_bridge"):
        in_commands = path.relative_to(REPO).parts[1] == "commands"
        for number, kind, header, under_cuda in includes(path):
            if header.startswith("cashash_cuda/") and not under_cuda:
                fail(path, number, f'"{header}" outside #ifdef CASHASH_WITH_CUDA')
            if header.startswith("colmap_bridge/commands/") and not in_commands:
                fail(path, number, f'cashash_bridge includes "{header}"')
            if header.startswith("synthetic/"):
                fail(path, number, f'cashash_bridge includes "{header}"')

    for rel, header in sorted(KNOWN_EXCEPTIONS - used_exceptions):
        problems.append(f"{rel}: the known exception for {header} is no longer needed; remove it here and in "
                        "docs/ARCHITECTURE.md")

    for problem in problems:
        print(problem)
    if problems:
        print(f"{len(problems)} include rule violation(s); docs/ARCHITECTURE.md, 'Who may use whom', has the rules")
        return 1
    print("include rules of docs/ARCHITECTURE.md hold")
    return 0


if __name__ == "__main__":
    sys.exit(main())
