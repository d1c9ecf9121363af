"""The byte scanner of OBJ files: the fast path of :func:`subtrace.io.obj.read_obj`.

:func:`scan_bytes` (jitted) reads v / vt / vn / f lines straight from the file's bytes and
lists every other statement for the statement reader (``ObjReader._statement``). It accepts
only what it can read exactly as the statement reader does and answers False for anything
else (a malformed or out-of-range value, a byte it cannot classify), after which the
statement reader reads the file again and reports it. :func:`scan` allocates its buffers.
Layout of what it fills: points / uvs / normals flat float64 (3, 2, 3 per element);
face_sizes (F,) int32; corners (3, C) int32 rows of 0-based v / vt / vn indices (-1 where
absent); other (n,4) int64 (start byte, end byte, line, faces so far) per other statement;
slow (n,4) int64 (start byte, end byte, block, index) per number left to float().
"""

from __future__ import annotations

import numpy as np

from subtrace.runtime.jit import nb

MAX_INDEX = 2**31 - 1  # indices are stored as int32

# Files of at most this many bytes go to the statement reader: it reads about 30 KB a
# millisecond, as fast as the scanner's kernel loads (Spot's 16 KB cage: `load` 0.015 s in
# a render's header either way; the 1.2 MB sword: 0.067 s against 0.025 s), and a cold
# render of a small cage then does not compile the scanner (about 1.2 s). `subtrace warmup`
# sets it to 0, so that the scanner compiles too.
STATEMENT_READER_BYTES = 64 << 10

_FAST_MAX_DIGITS = 18  # significant digits kept in an int64 mantissa (< 10^18)
_FAST_MAX_POW10 = 22  # 10^22 is the largest power of ten a double holds exactly
_POW10 = np.array([10.0**k for k in range(_FAST_MAX_POW10 + 1)])  # each exact


# byte classes: 1 whitespace inside a line for str.split() (\t \v \f \x1c-\x1f, space),
# 2 no more tokens after it on the line (\n, \r, the # of a comment)
_BYTE_CLASS = np.zeros(256, dtype=np.uint8)
_BYTE_CLASS[[9, 11, 12, 28, 29, 30, 31, 32]] = 1
_BYTE_CLASS[[10, 13, 35]] = 2


@nb.njit(cache=True)
def _is_space(b):
    return _BYTE_CLASS[b] == 1


@nb.njit(cache=True)
def _ends_tokens(b):
    return _BYTE_CLASS[b] == 2


@nb.njit(cache=True)
def _parse_float(data, a, b):
    """(code, value) of the token data[a:b]: code 0 for a value equal to float()'s, 1 for a
    decimal number float() must convert (too many digits or a large exponent), 2 for
    anything else.

    Clinger's fast path: a mantissa m <= 2^53 and a power 10^k with |k| <= 22 are exact
    doubles, so the single rounding of m * 10^k or m / 10^-k is the correctly rounded value.
    """
    i = a
    neg = False
    if data[i] == 43 or data[i] == 45:  # + or -
        neg = data[i] == 45
        i += 1
    mantissa = 0
    digits = 0  # significant digits in the mantissa
    point = 0  # digits of the mantissa after the decimal point
    seen = False
    exact = True
    after = False
    while i < b:
        c = data[i]
        if 48 <= c <= 57:
            seen = True
            if digits < _FAST_MAX_DIGITS:
                mantissa = mantissa * 10 + (c - 48)
                if mantissa > 0:
                    digits += 1
                if after:
                    point += 1
            else:
                exact = False  # a digit the mantissa cannot hold: float() converts this one
        elif c == 46 and not after:  # .
            after = True
        else:
            break
        i += 1
    if not seen:
        return 2, 0.0
    exponent = 0
    if i < b and (data[i] == 101 or data[i] == 69):  # e or E
        i += 1
        eneg = False
        if i < b and (data[i] == 43 or data[i] == 45):
            eneg = data[i] == 45
            i += 1
        if i == b:
            return 2, 0.0
        while i < b and 48 <= data[i] <= 57:
            if exponent < 100000:
                exponent = exponent * 10 + (data[i] - 48)
            i += 1
        if eneg:
            exponent = -exponent
    if i != b:
        return 2, 0.0
    if not exact:
        return 1, 0.0
    if mantissa == 0:
        return 0, -0.0 if neg else 0.0
    power = exponent - point
    if mantissa > 2**53 or power > _FAST_MAX_POW10 or power < -_FAST_MAX_POW10:
        return 1, 0.0
    scale = _POW10[abs(power)]
    value = mantissa * scale if power >= 0 else mantissa / scale
    return 0, -value if neg else value


@nb.njit(cache=True)
def _parse_index(data, a, b):
    """The OBJ index data[a:b] as written (1-based, or negative to count back); 0 for
    anything the statement reader would reject or convert differently."""
    i = a
    neg = False
    if i < b and (data[i] == 43 or data[i] == 45):
        neg = data[i] == 45
        i += 1
    if i == b or b - i > 10:
        return 0
    value = 0
    while i < b:
        c = data[i]
        if not 48 <= c <= 57:
            return 0
        value = value * 10 + (c - 48)
        i += 1
    if value > MAX_INDEX:
        return 0
    return -value if neg else value


# scan_bytes is one loop over the file's bytes (about 130 lines) and is not split: its
# state (byte position, line number, element / face / corner / statement counts) changes in
# every branch, so helpers would each take and return most of it, and the per-token calls
# sit on the hottest path of loading a cage. Each step carries a one-line comment instead.
@nb.njit(cache=True, nogil=True)
def scan_bytes(data, start, points, uvs, normals, face_sizes, corners, other, slow, counts):
    """Read the statements of `data` (uint8) from byte `start`; True when it read them all.

    Fills points / uvs / normals (flat float64), face_sizes and corners (3, C) int32 rows of
    v / vt / vn indices (-1 where absent); other (n,4) gets (start, end, line, faces so far)
    of every other statement, comment removed; slow (n,4) gets (start, end, block, index) of
    numbers for float() (block 0 points, 1 uvs, 2 normals). counts gets the numbers of
    points, uvs, normals, faces, corners, other statements and slow numbers.
    """
    n = len(data)
    elements = np.empty(3, dtype=np.int64)  # v, vt, vn statements read so far
    elements[:] = 0  # (not np.zeros: one allocator fewer for a cold render to compile)
    nf = nc = no = ns = 0
    number = 0
    i = start
    while i < n:
        number += 1
        # the keyword: 0 v, 1 vt, 2 vn, 3 f, -1 any other statement, and -2 none (a blank
        # or comment line)
        s = i
        j = s
        while j < n and _is_space(data[j]):
            j += 1
        k = j
        while k < n and _BYTE_CLASS[data[k]] == 0 and data[k] < 128:
            k += 1
        kind = -2 if k == j and (j == n or _ends_tokens(data[j])) else -1
        if k == n or _BYTE_CLASS[data[k]] != 0:
            if k - j == 1:
                kind = 0 if data[j] == 118 else (3 if data[j] == 102 else -1)
            elif k - j == 2 and data[j] == 118:
                kind = 1 if data[j + 1] == 116 else (2 if data[j + 1] == 110 else -1)
        # the tokens after the keyword; v / vn keep 3 numbers, vt 2 (w, colours ignored)
        width = 2 if kind == 1 else 3
        size = 0
        p = k
        while kind >= 0:
            while p < n and _is_space(data[p]):
                p += 1
            if p == n or _ends_tokens(data[p]):
                break
            q = p
            while q < n and _BYTE_CLASS[data[q]] == 0:
                q += 1
            if kind == 3:
                # a corner v, v/vt, v//vn or v/vt/vn, 0-based: negative indices count back
                # from the elements read so far, positive ones are checked at the end
                a = p
                b = p
                for field in range(3):
                    b = a
                    while b < q and data[b] != 47:  # /
                        b += 1
                    index = -1
                    if b > a or field == 0:
                        index = _parse_index(data, a, b)
                        if index > 0:
                            index -= 1
                        elif index < 0:
                            index += elements[field]
                        else:
                            return False
                        if index < 0:
                            return False
                    corners[field, nc + size] = index
                    a = b + 1
                if b < q:
                    return False  # a fourth field
            elif size < width:
                code, value = _parse_float(data, p, q)
                if code == 2:
                    return False
                index = width * elements[kind] + size
                if kind == 0:
                    points[index] = value
                elif kind == 1:
                    uvs[index] = value
                else:
                    normals[index] = value
                if code == 1:
                    slow[ns, 0] = p
                    slow[ns, 1] = q
                    slow[ns, 2] = kind
                    slow[ns, 3] = index
                    ns += 1
            else:
                break
            size += 1
            p = q
        # the rest of the line (ignored tokens, a comment) and its end: \n, \r or \r\n
        e = p
        end = -1
        while e < n and data[e] != 10 and data[e] != 13:
            if data[e] == 35 and end < 0:
                end = e
            e += 1
        i = e + 2 if e + 1 < n and data[e] == 13 and data[e + 1] == 10 else e + 1
        if kind == -2:
            continue
        if kind == -1:
            # any other statement, its comment removed, for the statement reader
            other[no, 0] = s
            other[no, 1] = e if end < 0 else end
            other[no, 2] = number
            other[no, 3] = nf
            no += 1
        elif kind == 3:
            if size < 3:
                return False
            face_sizes[nf] = size
            nf += 1
            nc += size
        else:
            if size < (1 if kind == 1 else 3):
                return False
            if size == 1:
                uvs[2 * elements[1] + 1] = 0.0  # vt u: v defaults to 0
            elements[kind] += 1
    # positive indices may name elements defined later: check them against the totals
    for c in range(nc):
        for field in range(3):
            if corners[field, c] >= elements[field]:
                return False
    counts[0] = elements[0]
    counts[1] = elements[1]
    counts[2] = elements[2]
    counts[3] = nf
    counts[4] = nc
    counts[5] = no
    counts[6] = ns
    return True


def scan(data: bytes):
    """Run :func:`scan_bytes` over ``data`` (a byte-order mark skipped) in buffers sized for
    the worst case; returns (points, uvs, normals, face_sizes, corners, other, slow, counts)
    as the module comment lays them out (counts: the numbers of points, uvs, normals, faces,
    corners, other statements and slow numbers), or None where the statement reader must
    read the file, as for a file of at most STATEMENT_READER_BYTES (which it reads the same:
    tests/test_obj.py)."""
    if len(data) <= STATEMENT_READER_BYTES:
        return None
    start = 3 if data.startswith(b"\xef\xbb\xbf") else 0
    max_lines = data.count(b"\n") + (data.count(b"\r") if b"\r" in data else 0) + 1
    points = np.empty(3 * max_lines)
    uvs = np.empty(2 * max_lines)
    normals = np.empty(3 * max_lines)
    face_sizes = np.empty(max_lines, dtype=np.int32)
    corners = np.empty((3, len(data) // 2 + 1), dtype=np.int32)
    other = np.empty((max_lines, 4), dtype=np.int64)
    slow = np.empty((3 * max_lines, 4), dtype=np.int64)
    counts = np.zeros(7, dtype=np.int64)
    buffer = np.frombuffer(data, dtype=np.uint8)
    if not scan_bytes(buffer, start, points, uvs, normals, face_sizes, corners, other, slow,
                      counts):
        return None
    return points, uvs, normals, face_sizes, corners, other, slow, counts
