"""Tables for people: pandas DataFrames when pandas is installed, else a dict of columns
(which ``pandas.DataFrame`` takes as is)."""

from typing import Any, Dict, List, Optional, Sequence


def frame(
    rows: Sequence[Dict[str, Any]],
    columns: Sequence[str],
    index: Optional[str] = None,
):
    """``rows`` (dicts) as a DataFrame with ``columns`` (and ``index`` as its index), or
    as a dict of column lists without pandas."""
    data: Dict[str, List[Any]] = {c: [r.get(c) for r in rows] for c in columns}
    try:
        import pandas as pd
    except ImportError:
        return data
    df = pd.DataFrame(data, columns=list(columns))
    if index is not None:
        df = df.set_index(index)
    return df


def square(values: Sequence[Sequence[float]], names: Sequence[str]):
    """A square matrix (correlations) labelled by ``names`` on both axes."""
    try:
        import pandas as pd
    except ImportError:
        return {"names": list(names), "values": [list(r) for r in values]}
    return pd.DataFrame([list(r) for r in values], index=list(names), columns=list(names))
