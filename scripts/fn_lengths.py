#!/usr/bin/env python3
"""The longest non-test functions of the workspace (brace to brace), and how many run over
100 and 150 lines: `python3 scripts/fn_lengths.py [N]` lists the N longest (default 20)."""
import re,subprocess,sys
files=subprocess.run("git ls-files '*.rs'",shell=True,capture_output=True,text=True).stdout.split()
res=[]
for f in files:
    if '/tests/' in f or f.startswith('tests/') or '/benches/' in f or f.startswith('benches') or '/examples/' in f: continue
    L=open(f).read().split('\n')
    # skip cfg(test) modules: find line index of '#[cfg(test)]' followed by mod
    test_start=None
    for i,l in enumerate(L):
        if l.startswith('#[cfg(test)]') and i+1<len(L) and L[i+1].startswith('mod '):
            test_start=i;break
    for i,l in enumerate(L):
        if test_start is not None and i>=test_start: break
        m=re.match(r'^(\s*)(pub(\([a-z]+\))? )?(const )?(async )?(unsafe )?fn (\w+)',l)
        if m:
            ind=m.group(1)
            # find end: line == ind+'}'
            for j in range(i+1,len(L)):
                if L[j]==ind+'}' : break
                if L[j].startswith(ind+'}') and L[j].strip()=='}': break
            else: continue
            # signature might end with ';' (trait decl)
            if ';' in l and '{' not in l and not any('{' in L[k] for k in range(i,min(i+8,len(L)))): continue
            res.append((j-i+1,f,m.group(7),i+1))
res.sort(reverse=True)
for r in res[:int(sys.argv[1]) if len(sys.argv)>1 else 20]: print(*r)
print('over100',sum(1 for r in res if r[0]>100),'over150',sum(1 for r in res if r[0]>150))
