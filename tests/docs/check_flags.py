"""Docs.FlagTablesMatchHelp: each program's --help and the docs' table of
its flags name the same flags.

A table is marked by a line '<!-- flags: PROGRAM [COMMAND] -->' before it
(docs/*.md); its first column names the flags. The help's flags are those
in its usage lines and those that open an indented line of its option list
(a flag mentioned inside another's text does not count). --help itself is
left out of both. Every program below must have a table, and terrane-world
one per command its help lists.

usage: check_flags.py SOURCE_DIR BIN_DIR"""
import os
import re
import subprocess
import sys

sys.dont_write_bytecode = True  # no __pycache__ in the source tree
from markdown_pages import flag_tables, pages, read

PROGRAMS = ["terrane-server", "terrane-bots", "terrane-admin", "terrane-view", "terrane-world"]
FLAG = re.compile(r"--[a-z0-9][a-z0-9-]*")


def help_text(bin_dir, words):
    r = subprocess.run([os.path.join(bin_dir, words[0]), *words[1:], "--help"], capture_output=True, text=True,
                       timeout=60)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(words)} --help exited {r.returncode}: {r.stderr}")
    return r.stdout + r.stderr


def help_flags(text):
    flags = set()
    in_usage = False
    for line in text.split("\n"):
        if line.startswith("usage:"):
            in_usage = True
        elif not line.strip():
            in_usage = False
        if in_usage:
            flags |= set(FLAG.findall(line))
        m = re.match(r"^\s+(--[a-z0-9][a-z0-9-]*)", line)
        if m:
            flags.add(m.group(1))
    flags.discard("--help")
    return flags


def world_commands(text):
    """The commands terrane-world's help lists under 'Commands:'."""
    commands = []
    in_list = False
    for line in text.split("\n"):
        if line.startswith("Commands:"):
            in_list = True
            continue
        if in_list:
            m = re.match(r"^  ([a-z]+)\s{2,}", line)
            if m:
                commands.append(m.group(1))
            elif not line.startswith(" "):
                in_list = False
    return commands


def main(source_dir, bin_dir):
    tables = {}
    for page in pages(source_dir):
        for words, flags in flag_tables(read(os.path.join(source_dir, page))):
            tables[" ".join(words)] = (page, flags - {"--help"})
    wanted = [p for p in PROGRAMS if p != "terrane-world"]
    wanted += ["terrane-world " + c for c in world_commands(help_text(bin_dir, ["terrane-world"]))]
    errors = []
    for name in wanted:
        if name not in tables:
            errors.append(f"{name}: no table of its flags in the docs (a line '<!-- flags: {name} -->' before it)")
            continue
        page, documented = tables[name]
        offered = help_flags(help_text(bin_dir, name.split()))
        for f in sorted(offered - documented):
            errors.append(f"{name}: {f} is in --help but not in {page}'s table")
        for f in sorted(documented - offered):
            errors.append(f"{name}: {f} is in {page}'s table but not in --help")
        print(f"{name}: {len(offered)} flags, {page}")
    for name in sorted(set(tables) - set(wanted)):
        errors.append(f"{tables[name][0]}: a flag table for '{name}', which is not a program or command here")
    for e in errors:
        print(e)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
