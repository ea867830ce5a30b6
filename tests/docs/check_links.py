"""Docs.LinksResolve: every relative link and image in README.md and
docs/*.md names a file or folder of the repository, and a '#anchor' a
heading of the page it points to. Also holds the manual to its shape:
README.md at most 400 lines, and no page speaking of how it was written
("this session", "the final code"): results carry dates and revisions.

usage: check_links.py SOURCE_DIR"""
import os
import re
import sys

sys.dont_write_bytecode = True  # no __pycache__ in the source tree
from markdown_pages import anchors, links, outside_code, pages, read

README_MAX_LINES = 400
# Phrases a page must not use: the project speaks of itself only.
WORDING = re.compile(r"this session|the final (code|commit)|this session's|one run on the final", re.I)


def main(source_dir):
    errors = []
    anchor_cache = {}

    def anchors_of(path):
        if path not in anchor_cache:
            anchor_cache[path] = anchors(read(path))
        return anchor_cache[path]

    checked = 0
    for page in pages(source_dir):
        path = os.path.join(source_dir, page)
        lines = read(path)
        if page == "README.md" and len(lines) - 1 > README_MAX_LINES:
            errors.append(f"README.md has {len(lines) - 1} lines, more than {README_MAX_LINES}: move detail to docs/")
        for n, text in outside_code(lines):
            m = WORDING.search(text)
            if m:
                errors.append(f"{page}:{n}: '{m.group(0)}': give the date and revision instead")
        for n, target in links(lines):
            if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
                continue
            checked += 1
            file_part, _, anchor = target.partition("#")
            dest = os.path.normpath(os.path.join(os.path.dirname(path), file_part)) if file_part else path
            if not os.path.exists(dest):
                errors.append(f"{page}:{n}: link to {target}: {os.path.relpath(dest, source_dir)} does not exist")
                continue
            if anchor and dest.endswith(".md") and anchor not in anchors_of(dest):
                errors.append(f"{page}:{n}: link to {target}: no heading with anchor #{anchor} in "
                              f"{os.path.relpath(dest, source_dir)}")
    for e in errors:
        print(e)
    print(f"{checked} relative links checked in {len(pages(source_dir))} pages, {len(errors)} problems")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
