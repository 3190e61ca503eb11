"""The compiled row loops of flexure.reduce (numba, compiled on first use and cached)."""

import numba
import numpy as np

@numba.njit(cache=True, nogil=True)
def count(indptr, indices, fdofs, fmap, gk, m, cnt):
    seen = np.zeros(m, np.bool_)
    for r in range(len(fdofs)):
        i = fdofs[r]
        c = 0
        seen[:] = False
        for p in range(indptr[i], indptr[i + 1]):
            j = indices[p]
            if fmap[j] >= 0:
                c += 1
            elif not seen[gk[j]]:
                seen[gk[j]] = True
                c += 6
        cnt[r] = c

@numba.njit(cache=True, nogil=True)
def fill(indptr, indices, data, fdofs, fmap, gk, gslot, G, m, nf, optr, oind, odat):
    acc = np.zeros(6 * m)
    seen = np.zeros(m, np.bool_)
    for r in range(len(fdofs)):
        i = fdofs[r]
        o = optr[r]
        seen[:] = False
        for p in range(indptr[i], indptr[i + 1]):
            j = indices[p]
            if fmap[j] >= 0:
                oind[o] = fmap[j]
                odat[o] = data[p]
                o += 1
            else:
                k = gk[j]
                if not seen[k]:
                    seen[k] = True
                    for c in range(6):
                        acc[6 * k + c] = 0.0
                v = data[p]
                s = gslot[j]
                for c in range(6):
                    acc[6 * k + c] += v * G[s, c]
        for k in range(m):
            if seen[k]:
                for c in range(6):
                    oind[o] = nf + 6 * k + c
                    odat[o] = acc[6 * k + c]
                    o += 1
