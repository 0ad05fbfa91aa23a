"""The docs' links and section references resolve, and the command lines they show exist (fast: text, the
CLI's parser and the default mission's config; nothing is simulated).

Checked in every tracked ``*.md`` (README.md, ARCHITECTURE.md, docs/, tests/data/):

* **Links and images** ``[text](target)`` / ``![alt](target)`` outside code (fenced blocks and inline
  code spans are skipped; ``http:``/``https:``/``mailto:`` targets too): the path, relative to the
  file that links, is a tracked file (or a folder holding tracked files); a ``#anchor`` on a ``.md``
  target (or alone, for the same file) is the slug of one of that file's headings, GitHub's rules:
  the heading's rendered text (link syntax reduced to its text), lower-cased, every character that
  is not a letter, digit, mark, space, ``-`` or ``_`` dropped, each space -> ``-``; a repeated slug
  gets ``-1``, ``-2`` ... in order. Anchors on other files may only be GitHub's line anchors ``#L12``.
* **Quoted section references**, the forms the docs use (found with grep): ``docs/X.md, "Text"``,
  ``[docs/X.md](docs/X.md), "Text"``, ``docs/X.md ("Text"`` and ``docs/X.md "Text"`` (a bare ``X.md``
  too; the quote may wrap a line), and inside one file ``see "Text"`` / ``section "Text"`` /
  ``under "Text"``, ``"Text" above`` / ``"Text" below`` (Text opening with a capital or a backtick)
  and ``**Text** above`` / ``**Text** below``. The path is read from the repository root, else from the
  folder of the file that quotes it, else from ``docs/``; the in-file forms name the file itself.
  The rule: compared case-insensitively, with backticks and ``*`` removed and whitespace collapsed
  (an ``...`` in the quote stands for any text), the quote names the sections **equal** to it, else
  those **opening** with it, else those **containing** it; at each of these steps the file's headings
  (any level) are tried before its bold paragraph leads (a paragraph opening with ``**Text**``, the
  notebooks' sub-sections). It must name exactly one: none is a dangling reference, two an
  ambiguous one ("sixth pass" when both ``mission`` and ``compare`` had a sixth pass).

Headings are ATX headings (``# ...``) outside fenced code; setext headings (underlined with ``===``)
are not used in these docs and are not read.

And the command lines the docs show (the CLI's parser and the default config, ~0.3 s, nothing run): every
``--option`` after ``dronewpt SUB`` (in prose, code spans or fenced blocks) or in a code span opening with a
subcommand (`` `compare --episodes 100` ``) is an option of that subcommand, and a value given to an option
with fixed choices (``--link envelope``, ``--format json``) is one of them; the text read runs to the end of
the code span or line, cut at ``|``, ``;``, ``&&``, `` #`` and ``) ``. A line that shows the refusal itself
(``unrecognized argument``, ``invalid choice``) is skipped: there the wrong option is the point. Likewise every
``--set KEY=VALUE`` key shown is one the default mission takes (``mission_sim.config.apply_overrides``), except on
a line showing its refusal (``is invalid``) and the keys in :data:`WRONG_ON_PURPOSE`.
"""

from __future__ import annotations

import functools
import itertools
import posixpath
import re
import subprocess
import unicodedata
from pathlib import Path
from urllib.parse import unquote

import pytest

ROOT = Path(__file__).resolve().parents[1]

_FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,})")
_HEADING = re.compile(r"^ {0,3}(#{1,6})[ \t]+(.*?)(?:[ \t]+#+)?[ \t]*$")
_CODE_SPAN = re.compile(r"(`+)(?:(?!\1)[^\n]|\n(?![ \t]*\n))+?\1")
_LINK = re.compile(r"(!?)\[((?:[^\[\]]|\[[^\[\]]*\])*)\]\(\s*<?([^()\s<>]*(?:\([^()\s]*\)[^()\s<>]*)*)>?"
                   r"(?:\s+(?:\"[^\"]*\"|'[^']*'))?\s*\)")
_SCHEME = re.compile(r"^(?:[a-zA-Z][a-zA-Z0-9+.-]*:|//)")
_MD_PATH = r"(?P<path>(?:[\w.-]+/)*[\w.-]+\.md)"
_QUOTE = r"\"(?P<quote>(?:[^\"\n]|\n(?![ \t]*\n)){1,300}?)\""   # may wrap a line, not a paragraph
_WS = r"[ \t]*\n?[ \t]*"   # blanks, at most one line break
#: docs/X.md, "Text" | [..](docs/X.md), "Text" | docs/X.md ("Text" | docs/X.md "Text"
_XREF = re.compile(r"(?:\[[^\[\]]*\]\()?" + _MD_PATH + r"(?:#[\w-]*)?\)?(?:," + _WS + r"|" + _WS + r"\(" + _WS
                   + r"|(?=\s)" + _WS + r")" + _QUOTE)
_SELFREF = re.compile(r"\b(?:[Ss]ee|[Ss]ection|[Uu]nder)(?=\s)" + _WS + _QUOTE
                      + r"|\"(?P<near>[A-Z`](?:[^\"\n]|\n(?![ \t]*\n)){0,300}?)\"" + _WS + r"(?:above|below)\b")
#: **Bold lead** below / above: a heading, or a paragraph that opens with that bold text
_BOLDREF = re.compile(r"(?<!\*)\*\*(?P<bold>[A-Za-z][^*\n]{0,80})\*\*,?" + _WS + r"(?:above|below)\b")
_LINE_ANCHOR = re.compile(r"^L\d+(?:-L\d+)?$")


def tracked_files(root: Path = ROOT) -> set[str]:
    """Repository-relative paths of the tracked files (every file under ``root`` outside a git checkout)."""
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=root, capture_output=True, check=True).stdout
        files = {p for p in out.decode().split("\0") if p}
    except (OSError, subprocess.CalledProcessError):
        files = set()
    if not files:
        files = {p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file() and ".git" not in p.parts}
    return {f for f in files if (root / f).exists()}


def prose_lines(text: str) -> list[str]:
    """The lines of ``text`` with fenced code blocks blanked (line numbers kept)."""
    out, fence = [], None
    for line in text.splitlines():
        m = _FENCE.match(line)
        if fence is None and m:
            fence = m.group(1)
            out.append("")
        elif fence is not None:
            if line.strip().startswith(fence[0] * len(fence)) and not line.strip().strip(fence[0]):
                fence = None
            out.append("")
        else:
            out.append(line)
    return out


def heading_text(raw: str) -> str:
    """A heading's rendered text: links and images reduced to their text, inline HTML tags dropped."""
    text = _LINK.sub(lambda m: m.group(2), raw)
    return re.sub(r"<[^>]+>", "", text).strip()


@functools.lru_cache(maxsize=None)
def headings(text: str) -> tuple[str, ...]:
    return tuple(heading_text(m.group(2)) for line in prose_lines(text) if (m := _HEADING.match(line)))


@functools.lru_cache(maxsize=None)
def bold_leads(text: str) -> tuple[str, ...]:
    """The bold text that opens a paragraph (``**Speed.** Medians ...`` -> ``Speed.``; it may wrap a line)."""
    lines, out = prose_lines(text), []
    for k, ln in enumerate(lines):
        if ln.startswith("**") and (k == 0 or not lines[k - 1].strip() or _HEADING.match(lines[k - 1])):
            para = "\n".join(itertools.takewhile(lambda x: x.strip(), lines[k:]))
            if m := re.match(r"\*\*(.+?)\*\*", para, flags=re.S):
                out.append(heading_text(" ".join(m.group(1).split())))
    return tuple(out)


def slug(text: str) -> str:
    """GitHub's anchor for a heading's text (github-slugger without the de-duplication)."""
    kept = "".join(c for c in text.lower() if c in " -_" or unicodedata.category(c)[0] in "LNM")
    return kept.replace(" ", "-")


@functools.lru_cache(maxsize=None)
def anchors(text: str) -> tuple[str, ...]:
    """Every heading's anchor in order, repeated slugs numbered as GitHub numbers them."""
    seen: dict[str, int] = {}
    out = []
    for h in headings(text):
        base = s = slug(h)
        while s in seen:
            seen[base] += 1
            s = f"{base}-{seen[base]}"
        seen[s] = 0
        seen.setdefault(base, 0)
        out.append(s)
    return tuple(out)


def _plain(s: str) -> str:
    return " ".join(s.replace("`", "").replace("*", "").replace("\u2019", "'").split()).lower()


def _matches(quote: str, heading: str) -> bool:
    """The quoted text is in the heading (case-insensitive; an ``...`` in the quote stands for any text)."""
    parts = [re.escape(p) for p in re.split(r"\s*\.\.\.\s*", _plain(quote))]
    return re.search(".*?".join(parts), _plain(heading)) is not None


def named_headings(quote: str, *groups: tuple[str, ...]) -> list[str]:
    """The names a quote picks: those equal to it, else those opening with it, else those containing it;
    at each step the first group that has one (headings before bold leads)."""
    q = _plain(quote)
    for test in (lambda h: _plain(h) == q, lambda h: _plain(h).startswith(q), lambda h: _matches(quote, h)):
        for names in groups:
            if hit := [h for h in names if test(h)]:
                return hit
    return []


class Docs:
    """The tracked files of one tree and the headings of its markdown files."""

    def __init__(self, root: Path, files: set[str]):
        self.root, self.files = root, files
        self.dirs = {posixpath.dirname(f) for f in files}
        self.dirs |= {d for f in files for d in _parents(f)}
        self._text: dict[str, str] = {}

    def text(self, rel: str) -> str:
        if rel not in self._text:
            self._text[rel] = (self.root / rel).read_text("utf-8")
        return self._text[rel]

    def resolve_quoted(self, src: str, path: str) -> str | None:
        for cand in (path, posixpath.join(posixpath.dirname(src), path), posixpath.join("docs", path)):
            cand = posixpath.normpath(cand)
            if cand in self.files:
                return cand
        return None


def _parents(f: str) -> list[str]:
    parts = f.split("/")[:-1]
    return ["/".join(parts[:k]) for k in range(1, len(parts) + 1)]


def _line(text: str, pos: int) -> int:
    return text.count("\n", 0, pos) + 1


def check_links(docs: Docs, src: str) -> tuple[int, list[str]]:
    """(number of relative links checked, problems) for the markdown file ``src``."""
    n, bad = 0, []
    text = _CODE_SPAN.sub(lambda c: re.sub(r"[^\n]", " ", c.group(0)), "\n".join(prose_lines(docs.text(src))))
    for m in _LINK.finditer(text):
        target = m.group(3)
        if not target or _SCHEME.match(target):
            continue
        n += 1
        path, _, anchor = target.partition("#")
        rel = posixpath.normpath(posixpath.join(posixpath.dirname(src), unquote(path))) if path else src
        where = f"{src}:{_line(text, m.start(3))}: ({target})"
        if rel not in docs.files and rel.rstrip("/") not in docs.dirs:
            bad.append(f"{where} {rel} is not a tracked file")
        elif anchor and rel.endswith(".md") and rel in docs.files:
            if anchor not in anchors(docs.text(rel)):
                bad.append(f"{where} no heading of {rel} has the anchor #{anchor}")
        elif anchor and not _LINE_ANCHOR.match(anchor):
            bad.append(f"{where} #{anchor} on a file that is not markdown")
    return n, bad


def check_quotes(docs: Docs, src: str) -> tuple[int, list[str]]:
    """(number of quoted section references checked, problems) for the markdown file ``src``."""
    bad = []
    text = "\n".join(prose_lines(docs.text(src)))
    xrefs = list(_XREF.finditer(text))
    refs = [(m.group("path"), m.group("quote"), m.start()) for m in xrefs]
    refs += [(None, m.group("quote") or m.group("near"), m.start()) for m in _SELFREF.finditer(text)
             if not any(r.start() <= m.start() < r.end() for r in xrefs)]
    refs += [(None, f"**{m.group('bold')}**", m.start()) for m in _BOLDREF.finditer(text)]
    for path, quote, pos in sorted(refs, key=lambda r: r[2]):
        quote = " ".join(quote.split())
        target = docs.resolve_quoted(src, path) if path else src
        where = f'{src}:{_line(text, pos)}: {path or "(this file)"}, "{quote}"'
        if target is None:
            bad.append(f"{where}: {path} is not a tracked file")
            continue
        named = named_headings(quote, headings(docs.text(target)), bold_leads(docs.text(target)))
        if len(named) != 1:
            bad.append(f"{where}: {len(named)} headings or bold leads of {target} match: " + " | ".join(named)
                       if named else f"{where}: no heading or bold lead of {target} has the quoted text")
    return len(refs), bad


def check_tree(root: Path, files: set[str] | None = None) -> tuple[int, int, list[str]]:
    """(links checked, quoted references checked, problems) over every tracked markdown file."""
    docs = Docs(root, tracked_files(root) if files is None else files)
    n_links = n_quotes = 0
    bad: list[str] = []
    for src in sorted(f for f in docs.files if f.endswith(".md")):
        k, b = check_links(docs, src)
        q, c = check_quotes(docs, src)
        n_links, n_quotes, bad = n_links + k, n_quotes + q, bad + b + c
    return n_links, n_quotes, bad


_SKIP_OPTION_LINE = re.compile(r"unrecognized argument|invalid choice")
_OPTION = re.compile(r"(?<![\w-])(--[a-z][\w-]*)(?:=(\S*))?")


def subcommand_options() -> dict[str, dict[str, tuple | None]]:
    """{subcommand: {option string: its choices (None: any value)}} of ``dronewpt``'s parser."""
    import argparse

    from mission_sim.cli import build_parser
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return {name: {s: (tuple(act.choices) if act.choices is not None and act.nargs in (None, "?") else None)
                   for act in sp._actions for s in act.option_strings}
            for name, sp in sub.choices.items()}


def check_options(text: str, src: str, options: dict[str, dict[str, tuple | None]]) -> tuple[int, list[str]]:
    """(number of option uses checked, problems) in the markdown ``text`` of ``src``."""
    names = "|".join(sorted(map(re.escape, options), key=len, reverse=True))
    use = re.compile(r"(?:`(?:dronewpt\s+)?|(?<![\w-])dronewpt\s+)(" + names + r")(?![\w-])([^`\n]*)")
    n, bad = 0, []
    for ln, line in enumerate(text.splitlines(), 1):
        if _SKIP_OPTION_LINE.search(line):
            continue
        for m in use.finditer(line):
            sub, rest = m.group(1), re.split(r"[|;]|&&|\)\s|\s#", m.group(2))[0]
            toks = rest.split()
            for k, tok in enumerate(toks):
                if not (o := _OPTION.fullmatch(tok.rstrip(",.:"))):
                    continue
                flag, n = o.group(1), n + 1
                if flag not in options[sub]:
                    bad.append(f"{src}:{ln}: dronewpt {sub} has no option {flag}")
                    continue
                choices = options[sub][flag]
                value = o.group(2) if o.group(2) is not None else (toks[k + 1] if k + 1 < len(toks) else "")
                value = value.strip("`,.;:'\"()")
                if choices is not None and value and not value.startswith("-") and value.isidentifier() \
                        and value not in choices:
                    bad.append(f"{src}:{ln}: dronewpt {sub} {flag} {value}: not one of {', '.join(choices)}")
    return n, bad


#: ``--set`` keys the docs show as bad input where the line does not say so (docs/performance.md's start-up checks)
WRONG_ON_PURPOSE = {"sim.nope"}
_SET_KEY = re.compile(r"--set[ =]`?([a-z_]+(?:\.\w+)+)=")


def check_set_keys(text: str, src: str, valid) -> tuple[int, list[str]]:
    """(number of ``--set KEY=`` keys checked, problems) in ``text``; ``valid(key)`` is None or the error."""
    n, bad = 0, []
    for ln, line in enumerate(text.splitlines(), 1):
        if "is invalid" in line:
            continue
        for m in _SET_KEY.finditer(line):
            if m.group(1) in WRONG_ON_PURPOSE:
                continue
            n += 1
            if (err := valid(m.group(1))) is not None:
                bad.append(f"{src}:{ln}: --set {m.group(1)}=...: {err}")
    return n, bad


def default_mission_key():
    """``valid(key)`` for :func:`check_set_keys`: None when the default mission takes ``key``, else the error."""
    from mission_sim.config import apply_overrides, load_config_dict
    base = load_config_dict()

    def valid(key):
        try:
            apply_overrides(base, {key: 1.0})
        except ValueError as exc:
            if str(exc).startswith("override key"):
                return str(exc).split(";")[0]
        return None
    return valid


# --- the checker on the repository -------------------------------------------------------------

def test_every_link_and_section_reference_resolves():
    n_links, n_quotes, bad = check_tree(ROOT)
    assert n_links >= 50 and n_quotes >= 50, (n_links, n_quotes)   # the docs are read at all
    assert not bad, f"{len(bad)} broken of {n_links} links and {n_quotes} quoted references:\n" + "\n".join(bad)


def test_every_option_the_docs_show_exists():
    options = subcommand_options()
    assert {"mission", "compare", "train", "sweep", "replay"} <= set(options)
    n, bad = 0, []
    for src in sorted(f for f in tracked_files(ROOT) if f.endswith(".md")):
        k, b = check_options((ROOT / src).read_text("utf-8"), src, options)
        n, bad = n + k, bad + b
    assert n >= 300, n   # the docs are read at all
    assert not bad, f"{len(bad)} of {n} options shown in the docs are not the command's:\n" + "\n".join(bad)


def test_every_set_key_the_docs_show_exists():
    valid = default_mission_key()
    n, bad = 0, []
    for src in sorted(f for f in tracked_files(ROOT) if f.endswith(".md")):
        k, b = check_set_keys((ROOT / src).read_text("utf-8"), src, valid)
        n, bad = n + k, bad + b
    assert n >= 50, n
    assert not bad, f"{len(bad)} of {n} --set keys shown in the docs are not the config's:\n" + "\n".join(bad)


# --- the checker on synthetic docs: it can fail ------------------------------------------------

@pytest.mark.parametrize("heading, anchor", [
    ("At scale: 100,000 cases", "at-scale-100000-cases"),
    ("The `model_based` policy (eq. 9)", "the-model_based-policy-eq-9"),
    ("Exact-mode link -> 0.14 % off", "exact-mode-link---014--off"),
    ("[Linked](other.md) heading", "linked-heading"),
    ("Issue 21's must-shows", "issue-21s-must-shows"),
])
def test_slug_follows_github(heading, anchor):
    assert slug(heading_text(heading)) == anchor


def test_repeated_headings_are_numbered():
    assert anchors("# A\n## Tried\n## Tried\n```\n## Tried\n```\n## Tried\n") == ("a", "tried", "tried-1", "tried-2")


def _tree(tmp_path: Path, docs: dict[str, str]) -> tuple[int, int, list[str]]:
    for rel, text in docs.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    return check_tree(tmp_path, set(docs))


def test_the_checker_finds_broken_links_and_references(tmp_path):
    target = ("# T\n\n## From Python\n\n## Sixth pass: the stop cache\n\n## Tried\n\n## Tried\n\n## Goal 2 (x)\n"
              "## Why (goal 2)\n\n**Third pass (2026-11-26, 07:35; under\nload).** Text.\n")
    good = ("# R\n![fig](img/a.png) [t](docs/t.md#from-python) [t](docs/t.md#tried-1) [x](#r) "
            "[s](https://example.org/x#y) `[code](nowhere.md)`\n"
            'docs/t.md, "From Python"; [docs/t.md](docs/t.md), "sixth pass"; docs/t.md ("Goal 2"; docs/t.md,\n'
            '"the stop\ncache"; **Speed** below; docs/t.md, "third pass (2026-11-26 ... load)"\n\n**Speed.** Fast.\n'
            '```\n[in a fence](missing.md) docs/t.md, "Not a heading"\n```\n')
    assert _tree(tmp_path / "a", {"README.md": good, "docs/t.md": target, "img/a.png": ""}) == (5, 6, [])
    broken = ("# R\n![fig](img/b.png) [t](docs/t.md#tried-2) [t](docs/gone.md) [x](#nope)\n"
              'docs/t.md, "Seventh pass"; t.md, "From Python"; see "R"; see "Q" below\n'
              'docs/gone.md, "X"; docs/t.md, "tried"; **Nothing** below\n')
    assert _tree(tmp_path / "b", {"README.md": broken, "docs/t.md": target, "img/a.png": ""}) == (4, 7, [
        "README.md:2: (img/b.png) img/b.png is not a tracked file",
        "README.md:2: (docs/t.md#tried-2) no heading of docs/t.md has the anchor #tried-2",
        "README.md:2: (docs/gone.md) docs/gone.md is not a tracked file",
        "README.md:2: (#nope) no heading of README.md has the anchor #nope",
        'README.md:3: docs/t.md, "Seventh pass": no heading or bold lead of docs/t.md has the quoted text',
        'README.md:3: (this file), "Q": no heading or bold lead of README.md has the quoted text',
        'README.md:4: docs/gone.md, "X": docs/gone.md is not a tracked file',
        'README.md:4: docs/t.md, "tried": 2 headings or bold leads of docs/t.md match: Tried | Tried',
        'README.md:4: (this file), "**Nothing**": no heading or bold lead of README.md has the quoted text',
    ])


def test_the_option_checker_finds_options_a_command_lacks():
    options = {"mission": {"--policy": None, "--format": ("table", "json"), "--set": None},
               "compare": {"--episodes": None, "--link": ("envelope", "modal")}}
    text = ("Run `dronewpt mission --policy step --format json` or `compare --episodes 3 --link=modal`.\n"
            "```\n$ dronewpt mission --set a=1 | grep x --nope\n```\n"
            "`mission --polcy step` gives `unrecognized argument '--polcy'`; `dronewpt mission --format xml`: invalid choice\n"
            "Then `dronewpt mission --polcy step` and `compare --episode 3 --link eq4`;\n"
            "dronewpt mission --format=yaml --set k=v; mission --bogus is prose, not a command\n")
    n, bad = check_options(text, "t.md", options)
    assert (n, bad) == (10, ["t.md:6: dronewpt mission has no option --polcy",
                            "t.md:6: dronewpt compare has no option --episode",
                            "t.md:6: dronewpt compare --link eq4: not one of envelope, modal",
                            "t.md:7: dronewpt mission --format yaml: not one of table, json"])


def test_the_set_key_checker_finds_keys_the_config_lacks():
    text = ("`dronewpt mission --set wind.speed_m_s=6 --set pads.0.hover_time_s=30`\n"
            "`mission --set wind.gust_sigma=3` and --set=battery.capacity=2\n"
            "| `mission --set nosuch.key=1` | 2 | `override key 'nosuch.key' is invalid` |\n"
            "`--set sim.nope=1` on purpose; `--set pads.7.x_m=1`\n")
    n, bad = check_set_keys(text, "t.md", default_mission_key())
    assert n == 5 and [b.split(": override")[0] for b in bad] == [
        "t.md:2: --set wind.gust_sigma=...", "t.md:2: --set battery.capacity=...", "t.md:4: --set pads.7.x_m=..."]
