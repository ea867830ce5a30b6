"""What the docs tests read from the manual: its pages (README.md and
docs/*.md), their headings' anchors, links, fenced code blocks and the
flag tables. Plain string and regex work on Markdown as the pages write it;
nothing here renders Markdown."""
import os
import re

FENCE = re.compile(r"^(```|~~~)")


def pages(source_dir):
    """README.md and every docs/*.md, as paths relative to source_dir."""
    found = ["README.md"]
    docs = os.path.join(source_dir, "docs")
    if os.path.isdir(docs):
        found += sorted("docs/" + f for f in os.listdir(docs) if f.endswith(".md"))
    return found


def read(path):
    with open(path, encoding="utf-8") as f:
        return f.read().split("\n")


def outside_code(lines):
    """(line number, text) of every line outside fenced code blocks, with
    inline code spans blanked out."""
    fenced = False
    for n, line in enumerate(lines, 1):
        if FENCE.match(line.strip()):
            fenced = not fenced
            continue
        if not fenced:
            yield n, re.sub(r"`[^`]*`", "``", line)


def slug(heading):
    """GitHub's anchor for a heading: lower case, punctuation dropped
    (letters, digits, spaces, '-' and '_' kept), spaces to '-'."""
    text = re.sub(r"[*`]|\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip().lower())
    text = "".join(c for c in text if c.isalnum() or c in " -_")
    return text.replace(" ", "-")


def anchors(lines):
    """Every heading's anchor; a repeated heading gets -1, -2, ... as on GitHub."""
    seen = {}
    result = set()
    fenced = False
    for line in lines:
        if FENCE.match(line.strip()):
            fenced = not fenced
            continue
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if fenced or not m:
            continue
        base = slug(m.group(1))
        n = seen.get(base, 0)
        seen[base] = n + 1
        result.add(base if n == 0 else f"{base}-{n}")
    return result


LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")


def links(lines):
    """(line number, target) of every inline link and image outside code."""
    for n, text in outside_code(lines):
        for m in LINK.finditer(text):
            yield n, m.group(1)


def marked_blocks(lines, marker):
    """Fenced code blocks right after a line '<!-- MARKER -->' (blank lines
    between allowed): (line number, language, [lines])."""
    blocks = []
    pending = False
    i = 0
    while i < len(lines):
        s = lines[i].strip()
        if s == f"<!-- {marker} -->":
            pending = True
        elif FENCE.match(s):
            lang = s[3:].strip()
            start = i + 1
            i += 1
            body = []
            while i < len(lines) and not FENCE.match(lines[i].strip()):
                body.append(lines[i])
                i += 1
            if pending:
                blocks.append((start, lang, body))
            pending = False
        elif s:
            pending = False
        i += 1
    return blocks


def flag_tables(lines):
    """Every table after a line '<!-- flags: PROGRAM [COMMAND] -->': the
    program's words, and the --flags named in the table's first column."""
    tables = []
    i = 0
    while i < len(lines):
        m = re.match(r"^<!-- flags: (.+?) -->$", lines[i].strip())
        i += 1
        if not m:
            continue
        while i < len(lines) and not lines[i].strip().startswith("|"):
            i += 1
        flags = set()
        row = 0
        while i < len(lines) and lines[i].strip().startswith("|"):
            if row >= 2:  # header and separator rows first
                first = lines[i].strip().strip("|").split("|")[0]
                flags |= set(re.findall(r"--[a-z0-9][a-z0-9-]*", first))
            row += 1
            i += 1
        tables.append((m.group(1).split(), flags))
    return tables
