#!/usr/bin/env python3
"""Checks the size rules of library code: no function longer than
MAX_FUNCTION_LINES lines or of cyclomatic complexity above
MAX_FUNCTION_COMPLEXITY (as lizard measures them), and no class or struct in
cuda/ longer than MAX_CLASS_LINES lines. Library code is everything under
LIBRARY_FOLDERS; tests/ and scripts/ are not. Prints every violation and
exits 1 on any; exits 1 too when lizard is not installed
(scripts/install_deps.sh installs it).

A class listed in KNOWN_LONG_CLASSES may stay above the limit until it is
split; an entry that no longer applies fails the check, so that the list
only shrinks.

Usage: code_size_rules.py [REPO]   (default: the repository of this script)
"""

import pathlib
import re
import sys

REPO = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else pathlib.Path(__file__).resolve().parents[2])

LIBRARY_FOLDERS = ["src", "cuda", "colmap_bridge", "distributed", "synthetic", "python", "app"]
MAX_FUNCTION_LINES = 120
MAX_FUNCTION_COMPLEXITY = 40
CLASS_FOLDERS = ["cuda"]
MAX_CLASS_LINES = 300

# Classes of CLASS_FOLDERS above MAX_CLASS_LINES today: (file, class).
KNOWN_LONG_CLASSES: set = set()

CXX_SUFFIXES = {".h", ".cc", ".cu", ".cuh"}
# lizard does not know CUDA's suffixes; their sources are C++ to it.
CUDA_SUFFIXES = {".cu", ".cuh"}
SOURCE_SUFFIXES = CXX_SUFFIXES | {".py"}


def sources(folders, suffixes):
    result = []
    for folder in folders:
        root = REPO / folder
        if root.exists():
            result.extend(p for p in root.rglob("*") if p.suffix in suffixes and p.is_file())
    return sorted(result)


def function_problems(lizard):
    problems = []
    for path in sources(LIBRARY_FOLDERS, SOURCE_SUFFIXES):
        rel = str(path.relative_to(REPO))
        name = rel + ".cpp" if path.suffix in CUDA_SUFFIXES else rel
        info = lizard.analyze_file.analyze_source_code(name, path.read_text(encoding="utf-8", errors="replace"))
        for function in info.function_list:
            if function.length > MAX_FUNCTION_LINES:
                problems.append(f"{rel}:{function.start_line}: {function.name} has {function.length} lines "
                                f"(at most {MAX_FUNCTION_LINES})")
            if function.cyclomatic_complexity > MAX_FUNCTION_COMPLEXITY:
                problems.append(f"{rel}:{function.start_line}: {function.name} has cyclomatic complexity "
                                f"{function.cyclomatic_complexity} (at most {MAX_FUNCTION_COMPLEXITY})")
    return problems


def without_comments_and_literals(text):
    """The text with comments and string and character literals blanked out,
    line breaks kept, so that braces count and line numbers stay."""
    out = []
    i, n = 0, len(text)
    while i < n:
        if text.startswith("//", i):
            end = text.find("\n", i)
            end = n if end < 0 else end
        elif text.startswith("/*", i):
            end = text.find("*/", i + 2)
            end = n if end < 0 else end + 2
        elif text[i] in "\"'":
            end = i + 1
            while end < n and text[end] != text[i] and text[end] != "\n":
                end += 2 if text[end] == "\\" else 1
            end += 1
        else:
            out.append(text[i])
            i += 1
            continue
        out.append(re.sub(r"[^\n]", " ", text[i:end]))
        i = end
    return "".join(out)


# class or struct NAME [final] [: bases] {   (not a declaration, a friend or
# an elaborated type: those have no body here)
CLASS_HEAD = re.compile(r"\b(?:class|struct)\s+(?:(?:__align__|alignas)\s*\(\s*\w+\s*\)\s+)?([A-Za-z_]\w*)\s*"
                        r"(?:final\s*)?(?::[^;{}()]*)?\{")


def classes(path):
    """(name, first line, lines) of each class and struct defined in `path`,
    from its head to its closing brace."""
    text = without_comments_and_literals(path.read_text(encoding="utf-8", errors="replace"))
    result = []
    for match in CLASS_HEAD.finditer(text):
        depth = 0
        end = len(text) - 1
        for j in range(match.end() - 1, len(text)):
            if text[j] == "{":
                depth += 1
            elif text[j] == "}":
                depth -= 1
                if depth == 0:
                    end = j
                    break
        first = text.count("\n", 0, match.start()) + 1
        last = text.count("\n", 0, end) + 1
        result.append((match.group(1), first, last - first + 1))
    return result


def class_problems():
    problems = []
    long_classes = set()
    for path in sources(CLASS_FOLDERS, CXX_SUFFIXES):
        rel = str(path.relative_to(REPO))
        for name, line, lines in classes(path):
            if lines <= MAX_CLASS_LINES:
                continue
            long_classes.add((rel, name))
            if (rel, name) not in KNOWN_LONG_CLASSES:
                problems.append(f"{rel}:{line}: class {name} has {lines} lines (at most {MAX_CLASS_LINES})")
    for rel, name in sorted(KNOWN_LONG_CLASSES - long_classes):
        problems.append(f"{rel}: class {name} is no longer above {MAX_CLASS_LINES} lines (or gone); remove it from "
                        "KNOWN_LONG_CLASSES in tests/architecture/code_size_rules.py")
    return problems


def main():
    try:
        import lizard  # noqa: PLC0415: only this check needs it
    except ImportError:
        print("code_size_rules.py needs the Python package lizard (pip install lizard, or scripts/install_deps.sh)")
        return 1
    problems = function_problems(lizard) + class_problems()
    for problem in problems:
        print(problem)
    if problems:
        print(f"{len(problems)} code size rule violation(s): split the function or class into parts with one job each")
        return 1
    print(f"code size rules hold: functions at most {MAX_FUNCTION_LINES} lines and complexity "
          f"{MAX_FUNCTION_COMPLEXITY}, classes of {', '.join(CLASS_FOLDERS)}/ at most {MAX_CLASS_LINES} lines "
          f"(but the {len(KNOWN_LONG_CLASSES)} of KNOWN_LONG_CLASSES)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
