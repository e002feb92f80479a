"""dup_prims.py IN K OUT: the NFF scene IN with every primitive (p, pp, s,
c) repeated K times in place, materials and everything else once (copies
of one primitive share its material).  Counts numbers, not lines: SPD
writes a cone on one line ("c bx by bz rb ax ay az ra"), classic NFF on
three (session 40's script took three lines for every cone and repeated
the two lines after it, materials among them: rings and lattice seemed
to shadow their copies)."""
import sys

src, k, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
L = open(src).read().split('\n')
o = []
i = 0


def take(i, need):
    """Lines from i holding the keyword and `need` numbers after it."""
    blk, got = [], -1
    while got < need:
        blk.append(L[i])
        got += len(L[i].split())
        i += 1
    return blk, i


while i < len(L):
    t = L[i].split()
    if t and t[0] in ('p', 'pp'):
        blk, i = take(i, 1 + (3 if t[0] == 'p' else 6) * int(t[1]))
    elif t and t[0] == 's':
        blk, i = take(i, 4)
    elif t and t[0] == 'c':
        blk, i = take(i, 8)
    else:
        o.append(L[i])
        i += 1
        continue
    o.extend(blk * k)
open(out, 'w').write('\n'.join(o))
