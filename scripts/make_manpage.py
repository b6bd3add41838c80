#!/usr/bin/env python3
"""Writes the lex3d(1) manual page from the command's own help.

    make_manpage.py LEX3D_BINARY OUT.1

The options of every command come from `lex3d --help-all` (so the page never disagrees
with the program); the page adds what help does not say: exit status, files, examples.
"""
import re
import subprocess
import sys


def roff(text):
    """Escapes text for roff (backslashes, leading dots and quotes)."""
    text = text.replace("\\", "\\e")
    return "\n".join(("\\&" + l) if l.startswith((".", "'")) else l for l in text.split("\n"))


def main():
    binary, out = sys.argv[1], sys.argv[2]
    version = subprocess.run([binary, "--version"], capture_output=True, text=True, check=True).stdout.strip()
    help_all = subprocess.run([binary, "--help-all"], capture_output=True, text=True, check=True).stdout
    lines = help_all.split("\n")
    # Commands start at column 0 after the "Subcommands:" line; their help is indented.
    start = next(i for i, l in enumerate(lines) if l.startswith("Subcommands:")) + 1
    commands, current = [], None
    for l in lines[start:]:
        if l and not l.startswith(" "):
            current = [l.strip(), []]
            commands.append(current)
        elif current is not None:
            current[1].append(l[2:] if l.startswith("  ") else l)
    page = [
        '.TH LEX3D 1 "" "%s" "User Commands"' % roff(version),
        ".SH NAME",
        "lex3d \\- compress lidar scans and maps with a learned alphabet, and recognise places",
        ".SH SYNOPSIS",
        ".B lex3d",
        ".I command",
        "[\\fIoptions\\fR] \\fIfiles\\fR...",
        ".br",
        ".B lex3d",
        "[\\fB\\-\\-help\\fR | \\fB\\-\\-help\\-all\\fR | \\fB\\-\\-version\\fR]",
        ".SH DESCRIPTION",
        "lex3d turns 3D lidar scans and maps (PCD, PLY, KITTI .bin, text, LAS, raw Ouster and",
        "Velodyne captures) into compact model files: the words of a learned alphabet of local",
        "structures placed with 6-DoF poses, and optionally a residual layer that bounds every",
        "point's error. It decodes them back to point clouds, reuses one alphabet across many scans,",
        "and finds where a scan was seen before from a database of coded scans.",
        "Every option shows its default; lengths are in metres unless the help says otherwise.",
        ".SH COMMANDS",
    ]
    # --help-all lists a command's subcommands (place build, ...) without their options:
    # each is asked for its own help.
    expanded = []
    for name, body in commands:
        expanded.append((name, body))
        if any(l.strip() == "Subcommands:" for l in body):
            at = next(i for i, l in enumerate(body) if l.strip() == "Subcommands:") + 1
            for l in body[at:]:
                m = re.match(r"^\s+([a-z][a-z0-9-]*)\s", l + " ")
                if not m:
                    continue
                sub = m.group(1)
                text = subprocess.run([binary, name, sub, "--help"], capture_output=True, text=True,
                                      check=True).stdout
                sub_lines = [x for x in text.split("\n") if not x.startswith("Usage:")]
                expanded.append(("%s %s" % (name, sub), sub_lines))
    for name, body in expanded:
        page.append(".SS %s" % roff(name))
        text = "\n".join(body).strip("\n")
        summary, _, rest = text.partition("\n")
        page.append(roff(summary.strip()))
        if rest.strip():
            page += [".PP", ".nf", ".RS 2", roff(rest.strip("\n").rstrip()), ".RE", ".fi"]
    page += [
        ".SH EXIT STATUS",
        ".TP", "0", "success",
        ".TP", "1", "usage error: an unknown command or option, a value out of range",
        ".TP", "2", "bad data: an input file is malformed, truncated or corrupt (the message names it)",
        ".TP", "3", "I/O error: a file cannot be read or written; no partial output is left",
        ".TP", "4", "out of memory: an input asked for more memory than there is",
        ".SH FILES",
        ".TP", ".I *.lex3dm", "a model file (one scan)",
        ".TP", ".I *.lex3da", "an alphabet file, shared by the models that reference it",
        ".TP", ".I *.lex3dq", "a sequence file: many scans and their shared alphabet",
        ".TP", ".I *.lex3dp", "a place database",
        ".PP",
        "The formats are specified in the formats/ folder of the source distribution.",
        ".SH EXAMPLES",
        ".nf",
        "lex3d compress scan.bin -o scan.lex3dm --max-error 0.01",
        "lex3d decompress scan.lex3dm -o scan.pcd",
        "lex3d compress seq/*.bin --learn-scans 5 --one-file -o seq.lex3dq --max-error 0.02",
        "lex3d place build map.lex3dp seq/*.bin --poses poses.txt",
        "lex3d place query map.lex3dp new_scan.bin --json",
        ".fi",
        ".SH SEE ALSO",
        "The README and the formats/ specifications of the lex3d source distribution.",
    ]
    with open(out, "w") as f:
        f.write("\n".join(page) + "\n")


if __name__ == "__main__":
    main()
