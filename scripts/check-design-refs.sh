#!/usr/bin/env bash
# Two checks a clone can make without building anything (issue 44):
#
# 1. Every "§N" reference in the repository resolves. A reference names a section of
#    the design document, docs/design.md, whose headings read "## §N. Title" (subsections
#    "### §N.M Title"); "§7–8" names both. A reference right after a Markdown file's
#    name ("`docs/results.md` §4") names that file's heading "## 4. …" instead. The
#    paper's sections are Roman (§IV-D) and never match; a reference right after
#    "VDA 5050" names the VDA specification's own section and is not checked.
# 2. Every relative link ("[text](path)") in README.md and docs/ resolves to a file or
#    directory of the repository (not one that .gitignore hides).
#
# Prints each failure with its file and line, and exits 1 if there was one.
set -euo pipefail
cd "$(dirname "$0")/.."
export LC_ALL=C
# Both checks list files through git; outside a checkout they would check nothing and pass.
if ! git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  echo "check-design-refs: $(pwd) is not a git checkout: nothing to check against" >&2
  exit 1
fi

failures=0

# 1. "§" references, in every text file git knows or would add (tracked, or untracked
# and not ignored), except this script.
refs=$(git grep -I -n --untracked -E '§ ?[0-9]' -- ':!scripts/check-design-refs.sh' || true)
bad_refs=$(printf '%s\n' "$refs" | awk '
  # The headings of a Markdown file, loaded once: heads[file, "N"] or heads[file, "N.M"].
  function load(file,    line, n) {
    if ((file, "") in loaded) return
    loaded[file, ""] = 1
    while ((getline line < file) > 0) {
      if (line !~ /^#+ /) continue
      sub(/^#+ /, "", line)
      sub(/^§ ?/, "", line)
      if (match(line, /^[0-9]+(\.[0-9]+)?/)) {
        n = substr(line, 1, RLENGTH)
        heads[file, n] = 1
      }
    }
    close(file)
  }
  function exists(path,    line) {
    if ((getline line < path) >= 0) { close(path); return 1 }
    return 0
  }
  # The Markdown file a reference in `src` names by `name` (as written), or "".
  function resolve(src, name,    dir, cand) {
    dir = src; sub(/[^\/]*$/, "", dir)
    cand = dir name; if (exists(cand)) return cand
    if (exists(name)) return name
    cand = "docs/" name; if (exists(cand)) return cand
    return ""
  }
  function report(where, ref, target, why) {
    printf "%s: %s does not resolve: %s\n", where, ref, why
  }
  NF == 0 { next }
  {
    # file:line:text (a file name has no colon in this repository)
    src = $0; sub(/:.*/, "", src)
    rest = substr($0, length(src) + 2)
    lineno = rest; sub(/:.*/, "", lineno)
    text = substr(rest, length(lineno) + 2)
    where = src ":" lineno
    while (match(text, /§ ?[0-9]+(\.[0-9]+)?((–|-)[0-9]+)?/)) {
      pre = substr(text, 1, RSTART - 1)
      ref = substr(text, RSTART, RLENGTH)
      text = substr(text, RSTART + RLENGTH)
      if (pre ~ /VDA 5050[^§]*$/) continue
      target = "docs/design.md"
      if (match(pre, /[A-Za-z0-9_.\/-]+\.md`? *$/)) {
        name = substr(pre, RSTART, RLENGTH); sub(/`? *$/, "", name)
        target = resolve(src, name)
        if (target == "") { report(where, ref, name, "no file " name); bad++; continue }
      }
      load(target)
      num = ref; sub(/^§ ?/, "", num)
      first = num; last = ""
      if (match(num, /(–|-)/)) { first = substr(num, 1, RSTART - 1); last = substr(num, RSTART + RLENGTH) }
      if (last == "") {
        if (!((target, first) in heads)) { report(where, ref, target, "no heading §" first " in " target); bad++ }
      } else {
        for (k = first + 0; k <= last + 0; k++)
          if (!((target, k "") in heads)) { report(where, ref, target, "no heading §" k " in " target); bad++ }
      }
    }
  }
')
if [ -n "$bad_refs" ]; then
  printf '%s\n' "$bad_refs"
  failures=$((failures + $(printf '%s\n' "$bad_refs" | wc -l)))
fi

# 2. Relative links in README.md and docs/.
while IFS= read -r md; do
  dir=$(dirname "$md")
  lineno=0
  while IFS= read -r line; do
    lineno=$((lineno + 1))
    case $line in *']('*) ;; *) continue ;; esac
    while read -r link; do
      [ -n "$link" ] || continue
      case $link in http://* | https://* | mailto:* | '#'*) continue ;; esac
      path=${link%%#*}
      path=${path%% *}
      if [ ! -e "$dir/$path" ] || git check-ignore -q "$dir/$path"; then
        echo "$md:$lineno: link ($link) does not resolve to a file of the repository"
        failures=$((failures + 1))
      fi
    done < <(printf '%s\n' "$line" | grep -oE '\]\([^)]+\)' | sed -E 's/^\]\((.*)\)$/\1/')
  done <"$md"
done < <(git ls-files --cached --others --exclude-standard -- README.md 'docs/*.md' 'docs/**/*.md' | sort -u)

if [ "$failures" -gt 0 ]; then
  echo "check-design-refs: $failures reference(s) or link(s) do not resolve" >&2
  exit 1
fi
echo "check-design-refs: every § reference and every link in README.md and docs/ resolves"
