"""Statistics of the benchmark tables: sample spread with its n, paired differences with t-intervals.

- :func:`realization_units`: the (seed, realization) units of reconstruction records.
- :func:`summary`: mean and sample standard deviation (ddof = 1) of the successful runs, with n and
  the number of failed runs (a failed reconstruction is a result: counted, never skipped).
- :func:`rank`: rows ordered best first by (failures, mean): a row with a failed reconstruction
  ranks after every row without one (a failure ranks last), whatever its mean.
- :func:`paired_difference`: d_i = a_i - b_i over the units (scenario, seed, realization) where both
  succeeded, mean d and its 95 % t-interval  mean +- t_{0.975, n-1} s_d / sqrt(n)  (scipy.stats.t);
  units where either failed are counted apart. n < 2 gives no interval (NaN bounds).
"""
from __future__ import annotations

import math
from typing import Hashable, Mapping, Optional, Sequence

import numpy as np


def realization_units(records: Mapping[int, dict], realizations: int, key: str = 'chamfer') -> dict:
    """(seed, realization) -> ``key`` of each seed's reconstruction record (``per_realization``
    entries, as ``common.reconstruct_record`` writes them), None where it failed or is missing: a
    record without entries (the plan failed) fails all ``realizations``."""
    units = {}
    for seed, record in sorted(records.items()):
        per = {p.get('realization', i): p.get(key) for i, p in enumerate(record.get('per_realization') or [])}
        for k in range(realizations):
            units[(seed, k)] = per.get(k)
    return units


def summary(values: Mapping[Hashable, Optional[float]]) -> dict:
    """{'mean', 'std' (ddof 1), 'n', 'failed'} of unit -> value (None or NaN: a failed run)."""
    ok = np.array([v for v in values.values() if v is not None and math.isfinite(v)], dtype=float)
    return {'mean': float(ok.mean()) if len(ok) else float('nan'),
            'std': float(ok.std(ddof=1)) if len(ok) > 1 else float('nan'),
            'n': int(len(ok)), 'failed': int(len(values) - len(ok))}


def rank_key(s: dict) -> tuple:
    """Sort key of a :func:`summary` (lower is better): fewer failures first, then lower mean (NaN
    means last)."""
    return (s['failed'] > 0, s['failed'], math.isnan(s['mean']), s['mean'] if not math.isnan(s['mean']) else 0.0)


def rank(summaries: Mapping[str, dict]) -> list[str]:
    """Row names best first: fewer failures first, then lower mean (NaN means last; :func:`rank_key`)."""
    return sorted(summaries, key=lambda name: rank_key(summaries[name]))


def paired_difference(a: Mapping[Hashable, Optional[float]], b: Mapping[Hashable, Optional[float]],
                      level: float = 0.95) -> dict:
    """Mean of a - b over the units both have succeeded on, with its ``level`` t-interval;
    ``only_a_failed`` / ``only_b_failed`` / ``both_failed`` / ``missing`` count the other units."""
    from scipy.stats import t

    def good(v) -> bool:
        return v is not None and math.isfinite(v)

    units = sorted(set(a) | set(b), key=repr)
    d = np.array([a[u] - b[u] for u in units if u in a and u in b and good(a[u]) and good(b[u])], dtype=float)
    out = {'mean': float(d.mean()) if len(d) else float('nan'), 'n': int(len(d)), 'level': level,
           'low': float('nan'), 'high': float('nan'),
           'only_a_failed': sum(1 for u in units if u in a and u in b and not good(a[u]) and good(b[u])),
           'only_b_failed': sum(1 for u in units if u in a and u in b and good(a[u]) and not good(b[u])),
           'both_failed': sum(1 for u in units if u in a and u in b and not good(a[u]) and not good(b[u])),
           'missing': sum(1 for u in units if u not in a or u not in b)}
    if len(d) > 1:
        half = float(t.ppf(0.5 + level / 2, len(d) - 1) * d.std(ddof=1) / math.sqrt(len(d)))
        out['low'], out['high'] = out['mean'] - half, out['mean'] + half
    return out


def paired_interval(base: Sequence[Optional[float]], other: Sequence[Optional[float]], level: float = 0.95) -> dict:
    """other - base, unit by unit in order (:func:`paired_difference`), as ``{'n', 'mean', 'ci95'}``:
    ``mean`` None without a pair, ``ci95`` None with fewer than 2."""
    d = paired_difference(dict(enumerate(other)), dict(enumerate(base)), level)
    return {'n': d['n'], 'mean': d['mean'] if d['n'] else None,
            'ci95': [d['low'], d['high']] if d['n'] > 1 else None}


def describe(s: dict, digits: int = 3, note: str = '') -> str:
    """'mean +- std (n=.., k failed; note)' of a :func:`summary`; one value has no sample std:
    'mean (n=1; ...)'."""
    failed = f', {s["failed"]} failed' if s['failed'] else ''
    tail = f'{failed}; {note}' if note else failed
    if not s['n']:
        return f'failed (n=0{tail})'
    spread = f' +- {s["std"]:.{digits}f}' if s['n'] > 1 else ''
    return f'{s["mean"]:.{digits}f}{spread} (n={s["n"]}{tail})'


def describe_difference(d: dict) -> str:
    """'mean [low, high] (n=..)' of a :func:`paired_difference`, with its failures."""
    fails = [f'{d[k]} {k.replace("_", " ")}' for k in ('only_a_failed', 'only_b_failed', 'both_failed', 'missing') if d[k]]
    if not d['n']:
        return 'no pair (n=0' + (', ' + ', '.join(fails) if fails else '') + ')'
    interval = f' [{d["low"]:+.3f}, {d["high"]:+.3f}]' if d['n'] > 1 else ''  # one pair: no interval
    return (f'{d["mean"]:+.3f}{interval} (n={d["n"]}'
            + (', ' + ', '.join(fails) if fails else '') + ')')


def spearman(x: Sequence[float], y: Sequence[float]) -> float:
    """Spearman's rho of x and y (scipy; ties share their mean rank, an infinity ranks at its end:
    a failure given -inf ranks last); NaN for fewer than 3 pairs or a side of one value."""
    from scipy.stats import spearmanr

    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if len(x) < 3 or len(np.unique(x)) < 2 or len(np.unique(y)) < 2:
        return float('nan')
    return float(spearmanr(x, y).statistic)
