"""Degrees from a coefficient count, counted as paper 003 counts them.

Paper 003 names its approximations by their number of coefficients: approximation I
with (n+1)(m+1) = 66 (n = 5 in p, m = 10 in u) and approximation II with
(n+1) + (m+1) + (l+1) = 15 (phi, psi and Gamma of degrees 5, 5 and 2, Gamma's forced
constant included). ``workbench identify valve --coefficients N`` uses these counts.
"""

from __future__ import annotations

from ...errors import InputError

__all__ = ["PAPER_DEGREES", "polynomial_degrees", "affine_structure", "affine_count"]

#: Paper 003's degrees: approximation I (n, m) and II (phi, psi, Gamma).
PAPER_DEGREES = {"I": (5, 10), "II": (5, 5, 2)}


def polynomial_degrees(count: int) -> tuple[int, int]:
    """(n, m) with (n+1)(m+1) = ``count``, n >= 1 and m >= 1, the degree in u about twice
    the degree in p as in paper 003 (n = 5, m = 10 for 66): the pair minimising |m - 2n|.

    Raises
    ------
    InputError
        When no such pair exists (``count`` prime, or < 4).
    """
    pairs = [(a - 1, count // a - 1) for a in range(2, count) if count % a == 0
             and count // a >= 2]
    if not pairs:
        raise InputError(f"{count} coefficients cannot be written (n+1)(m+1) with n, m >= 1; "
                         "give --degrees N M", location="--coefficients")
    return min(pairs, key=lambda nm: (abs(nm[1] - 2 * nm[0]), -nm[1]))


def affine_count(phi: int | None, psi: int, gamma: int, shared_psi: bool) -> int:
    """Paper 003's count of approximation II: (phi+1) + (psi+1) per psi branch + (gamma+1).

    ``gamma`` is the number of odd Gamma terms (the degree l), its constant (forced to 0
    by Gamma(0) = 0) is counted as the paper does."""
    return (0 if phi is None else phi + 1) + (psi + 1) * (1 if shared_psi else 2) + gamma + 1


def affine_structure(count: int) -> tuple[int, int, int, bool]:
    """(phi degree, psi degree, Gamma terms, shared psi) with paper 003's count ``count``.

    phi and psi share one degree n; among the structures that give ``count`` the one
    closest to the paper's (5, 5, 2) is chosen (Gamma degree 2 first, then n nearest 5,
    then two psi branches): 15 gives the paper's n = 5 with one psi, 21 the two-branch
    n = 5.

    Raises
    ------
    InputError
        When no structure with n <= 12 and Gamma degree 1 ... 4 has that count.
    """
    found = [(n, n, g, sh) for n in range(0, 13) for g in range(1, 5) for sh in (False, True)
             if affine_count(n, n, g, sh) == count]
    if not found:
        raise InputError(f"no approximation II structure has {count} coefficients (paper "
                         "count (n+1) + (n+1) per psi branch + (l+1)); e.g. 15 (one psi, "
                         "degrees 5 5 2) or 21 (two psi)", location="--coefficients")
    return min(found, key=lambda s: (abs(s[2] - 2), abs(s[0] - 5), s[3]))
