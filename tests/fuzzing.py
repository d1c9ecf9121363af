"""Hypothesis strategies shared by the readers' fuzz tests (test_obj.py, test_bad_inputs.py)."""

from __future__ import annotations

from hypothesis import strategies as st


def mutations(valid: str, alphabet: str, max_text: int, max_drop: int):
    """Bytes near a valid file ``valid``: random bytes, the file with junk inserted or a run
    of up to ``max_drop`` bytes cut out, or up to ``max_text`` characters of ``alphabet``."""
    raw = valid.encode()
    return st.one_of(
        st.binary(max_size=200),
        st.builds(lambda cut, junk: raw[:cut] + junk + raw[cut:],
                  st.integers(0, len(raw)), st.binary(max_size=12)),
        st.builds(lambda cut, n: raw[:cut] + raw[cut + n:],
                  st.integers(0, len(raw)), st.integers(1, max_drop)),
        st.text(alphabet=alphabet, max_size=max_text).map(str.encode),
    )
