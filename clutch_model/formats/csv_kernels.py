"""Compiled assembly of CSV rows from per-column texts (``table_csv.format_block``)."""
import numpy as np
from numba import njit

COMMA, OPEN, NULL_N, CR, LF = 44, 91, 110, 13, 10


@njit(cache=True, nogil=True)
def assemble_rows(text, bounds, row_field, prefix):
    """CSV rows: ``prefix`` (row label and comma), then per column the field
    ``row_field[c, k]`` of column c's JSON array text ``text[bounds[c, 0]:bounds[c, 1]]``
    (``[v0,v1,...]``; ``null`` -> empty field), comma-separated, CRLF-terminated. Returns the
    uint8 array of the rows."""
    ncols, nrows = row_field.shape
    # field j of column c spans starts[c, j] .. starts[c, j + 1] - 2 (the comma or bracket after it)
    maxf = 0
    counts = np.zeros(ncols, dtype=np.int64)
    for c in range(ncols):
        a, b = bounds[c, 0], bounds[c, 1]
        m = 1
        for i in range(a + 1, b - 1):
            if text[i] == COMMA:
                m += 1
        counts[c] = m
        if m > maxf:
            maxf = m
    starts = np.empty((ncols, maxf + 1), dtype=np.int64)
    for c in range(ncols):
        a, b = bounds[c, 0], bounds[c, 1]
        j = 0
        starts[c, 0] = a + 1
        for i in range(a + 1, b - 1):
            if text[i] == COMMA:
                j += 1
                starts[c, j] = i + 1
        starts[c, j + 1] = b                    # one past the closing bracket
    total = nrows * (prefix.size + ncols + 1)
    for c in range(ncols):
        for k in range(nrows):
            j = row_field[c, k]
            if text[starts[c, j]] != NULL_N:
                total += starts[c, j + 1] - 1 - starts[c, j]
    out = np.empty(total, dtype=np.uint8)
    o = 0
    for k in range(nrows):
        for i in range(prefix.size):
            out[o] = prefix[i]
            o += 1
        for c in range(ncols):
            if c:
                out[o] = COMMA
                o += 1
            j = row_field[c, k]
            a = starts[c, j]
            b = starts[c, j + 1] - 1
            if text[a] == NULL_N:
                continue
            for i in range(a, b):
                out[o] = text[i]
                o += 1
        out[o] = CR
        out[o + 1] = LF
        o += 2
    return out[:o]
