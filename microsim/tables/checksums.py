"""Every dataset of a table carries two checksums: HDF5's Fletcher-32 of each chunk, and the
SHA-256 of its bytes in its ``sha256`` attribute, which the reader compares with the bytes it reads."""

from __future__ import annotations

import hashlib

import numpy as np


def store(group, name: str, data) -> None:
    """One dataset with a Fletcher-32 checksum (h5py stores it chunked, as the checksum needs) and
    the SHA-256 of its bytes in an attribute: Fletcher-32 passes a chunk zeroed with its checksum,
    the digest (in the object header, which the 1.10 format checksums) does not."""
    data = np.asarray(data)
    dataset = group.create_dataset(name, data=data, fletcher32=True)
    dataset.attrs["sha256"] = digest(data)


def digest(data: np.ndarray) -> str:
    """The SHA-256 of the array's bytes in C order, in hex."""
    return hashlib.sha256(np.ascontiguousarray(data).tobytes()).hexdigest()
