"""The API reference of docs/python.md, generated from the terrane package's
docstrings (the C++ bindings' and terrane/__init__.py's), between the lines
'<!-- api:begin -->' and '<!-- api:end -->'.

  python_api.py SOURCE_DIR            rewrites the section
  python_api.py SOURCE_DIR --check    exits 1 if the section is not what
                                      the docstrings say (Docs.PythonApi)

Run with the terrane package importable (PYTHONPATH=build/python).
"""
import inspect
import os
import re
import sys

sys.dont_write_bytecode = True  # no __pycache__ in the source tree

import terrane  # noqa: E402

BEGIN, END = "<!-- api:begin -->", "<!-- api:end -->"

FUNCTIONS = ["connect", "ready", "loaded", "event", "walk", "pace", "paced", "synced", "in_thread", "follow",
             "keep_away"]
CLASSES = ["Client", "EditFuture", "Swarm", "Update", "Loaded", "Presence", "Player", "Message", "Disconnect",
           "Reconnected", "EditRejected", "EditOutcomeUnknown", "Unreachable"]


def clean(text):
    """A pybind11 signature or docstring as a reader wants it."""
    text = text.replace("terrane._native.", "")
    text = re.sub(r"\(self(: \w+)?(, )?", "(", text)
    return text.strip()


def split_doc(doc):
    """(signature, text) of a pybind11 docstring; (None, doc) otherwise."""
    doc = inspect.cleandoc(doc or "")
    first, _, rest = doc.partition("\n")
    if re.match(r"^\w+\(.*\)( -> .*)?$", first):
        return clean(first), clean(rest)
    return None, clean(doc)


def describe(name, obj):
    if isinstance(obj, property):
        return "`%s` (property)" % name, clean(obj.__doc__ or "")
    if inspect.isfunction(obj) or inspect.iscoroutinefunction(obj):
        prefix = "async " if inspect.iscoroutinefunction(obj) else ""
        return "`%s%s%s`" % (prefix, name, inspect.signature(obj)), clean(inspect.getdoc(obj) or "")
    sig, text = split_doc(getattr(obj, "__doc__", ""))
    return "`%s`" % (sig or name), text


def members(cls):
    out = []
    for name, obj in vars(cls).items():
        if name.startswith("_") and name not in ("__init__", "__await__"):
            continue
        if name == "__init__" and (getattr(obj, "__doc__", "") or "").startswith("Initialize self"):
            continue  # not made directly
        if name == "kind":
            out.append(("`kind`", "'%s'" % getattr(cls, name)))
        elif isinstance(obj, property) or callable(obj):
            out.append(describe(name, obj))
    return out


def render():
    lines = ["## API reference", "",
             "Generated from the docstrings (`tests/docs/python_api.py`; `help(terrane.Client)` says the same).", ""]
    lines += ["### Functions", ""]
    for name in FUNCTIONS:
        head, text = describe(name, getattr(terrane, name))
        lines += ["- %s" % head] + (["  " + t if t else "" for t in text.splitlines()] if text else []) + [""]
    for cname in CLASSES:
        cls = getattr(terrane, cname)
        lines += ["### %s" % cname, ""]
        doc = clean(inspect.getdoc(cls) or "")
        if doc:
            lines += [doc, ""]
        if issubclass(cls, BaseException):
            continue
        for head, text in members(cls):
            lines += ["- %s" % head] + (["  " + t if t else "" for t in text.splitlines()] if text else []) + [""]
    return "\n".join(line.rstrip() for line in lines).rstrip() + "\n"


def main(source, *flags):
    page = os.path.join(source, "docs", "python.md")
    text = open(page, encoding="utf-8").read()
    if BEGIN not in text or END not in text:
        sys.exit("%s: no '%s' ... '%s' section" % (page, BEGIN, END))
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    new = head + BEGIN + "\n" + render() + END + tail
    if "--check" in flags:
        if new != text:
            sys.exit("%s: the API reference differs from the docstrings; run "
                     "PYTHONPATH=build/python python3 tests/docs/python_api.py . to rewrite it" % page)
        print("docs/python.md's API reference matches the docstrings")
        return
    with open(page, "w", encoding="utf-8") as f:
        f.write(new)


if __name__ == "__main__":
    main(*sys.argv[1:])
