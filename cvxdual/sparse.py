"""The one scatter of element blocks into a sparse matrix, used by every assembly."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def assemble_blocks(rows: np.ndarray, cols: np.ndarray, blocks: np.ndarray, shape: tuple[int, int],
                    fmt: str = "csr") -> sp.spmatrix:
    """``sum_e`` of ``blocks[e]`` ``(a, b)`` placed at rows ``rows[e]`` ``(a,)`` and columns
    ``cols[e]`` ``(b,)``; duplicates add up, and entries with a negative row or column index
    (fixed or eliminated dofs) are dropped."""
    n, a, b = blocks.shape
    R = np.broadcast_to(np.asarray(rows)[:, :, None], (n, a, b))
    C = np.broadcast_to(np.asarray(cols)[:, None, :], (n, a, b))
    keep = (R >= 0) & (C >= 0)
    # int32 indices: half the memory of the default int64 for meshes below 2**31 entries
    itype = np.int32 if max(shape) < 2**31 - 1 else np.int64
    m = sp.coo_matrix((blocks[keep], (R[keep].astype(itype), C[keep].astype(itype))), shape=shape)
    return m.asformat(fmt)
