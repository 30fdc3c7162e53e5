"""Compiled assembly of CSV rows from per-column texts (``table_csv.format_block``)."""
import numpy as np
from numba import njit, uint64

COMMA, NULL_N, CR, LF = 44, 110, 13, 10


@njit(cache=True, nogil=True, boundscheck=False)
def assemble_rows(text, bounds, nfields, row_field, ident, prefix):
    """CSV rows: ``prefix`` (row label and comma), then per column c its field (row k's own
    if ``ident[c]``, else ``row_field[c, k]``) of the JSON array text
    ``text[bounds[c, 0]:bounds[c, 1]]`` (``[v0,v1,...]``, ``nfields[c]`` values; ``null`` ->
    empty field), comma-separated, CRLF-terminated. Returns the uint8 array of the rows.
    (Unsigned indices: no negative-index wrap-around code in the byte loops.)"""
    ncols = bounds.shape[0]
    nrows = row_field.shape[1]
    maxf = 1
    for c in range(ncols):
        maxf = max(maxf, nfields[c])
    fs = np.empty((ncols, maxf), dtype=np.uint64)    # field start
    fl = np.empty((ncols, maxf), dtype=np.uint64)    # field length (0: null)
    total = uint64(nrows * (prefix.size + ncols + 1))
    for c in range(ncols):
        a = uint64(bounds[c, 0] + 1)
        b = uint64(bounds[c, 1] - 1)
        j = 0
        s = a
        i = a
        while i < b:
            if text[i] == COMMA:
                fs[c, j] = s
                fl[c, j] = i - s
                j += 1
                s = i + uint64(1)
            i += uint64(1)
        fs[c, j] = s
        fl[c, j] = b - s
        for f in range(j + 1):
            if text[fs[c, f]] == NULL_N:
                fl[c, f] = 0
        if ident[c]:
            for f in range(j + 1):
                total += fl[c, f]
        else:
            for k in range(nrows):
                total += fl[c, row_field[c, k]]
    out = np.empty(total, dtype=np.uint8)
    o = uint64(0)
    npre = uint64(prefix.size)
    for k in range(nrows):
        for i in range(npre):
            out[o + uint64(i)] = prefix[i]
        o += npre
        for c in range(ncols):
            f = k if ident[c] else row_field[c, k]
            n_bytes = fl[c, f]
            a = fs[c, f]
            for i in range(n_bytes):
                out[o + uint64(i)] = text[a + uint64(i)]
            o += n_bytes
            out[o] = COMMA
            o += uint64(1)
        out[o - uint64(1)] = CR                         # the last comma becomes the line end
        out[o] = LF
        o += uint64(1)
    return out
