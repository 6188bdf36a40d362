#!/usr/bin/env python3
"""Check every relative markdown link in README.md and docs/**/*.md: file exists, anchor exists."""
import re, sys, pathlib, unicodedata
root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else '.')
files = [root / 'README.md'] + sorted((root / 'docs').rglob('*.md'))
link_re = re.compile(r'(?<!\!)\[(?:[^\]\[]|\[[^\]]*\])*\]\(([^)\s]+)\)|!\[[^\]]*\]\(([^)\s]+)\)')

def slugs(path):
    out = set(); counts = {}
    incode = False
    for line in path.read_text().splitlines():
        if line.startswith('```'):
            incode = not incode
        if incode:
            continue
        m = re.match(r'^(#{1,6})\s+(.*)$', line)
        if not m:
            continue
        t = m.group(2).strip().lower()
        t = re.sub(r'[^\w\- ]', '', t, flags=re.UNICODE)  # GitHub: drop punctuation
        t = t.replace(' ', '-')
        n = counts.get(t, 0); counts[t] = n + 1
        out.add(t if n == 0 else f'{t}-{n}')
    return out

bad = 0; total = 0
for f in files:
    text = f.read_text()
    # strip fenced code
    text_nc = re.sub(r'```.*?```', '', text, flags=re.S)
    for m in link_re.finditer(text_nc):
        target = m.group(1) or m.group(2)
        if re.match(r'^[a-z]+:', target):
            continue
        total += 1
        path, _, anchor = target.partition('#')
        dest = f if path == '' else (f.parent / path)
        if not dest.exists():
            print(f'{f.relative_to(root)}: missing file: {target}'); bad += 1; continue
        if anchor and dest.suffix == '.md':
            if anchor not in slugs(dest):
                print(f'{f.relative_to(root)}: missing anchor: {target}'); bad += 1
print(f'{total} relative links checked, {bad} broken')
sys.exit(1 if bad else 0)
