"""Projector contents in use by a render: their atlases, each built once however
many cameras need it, in a small thread pool (drawing a pattern is partly Python,
the pyramid is OpenCV work that releases the interpreter lock).
"""

from __future__ import annotations

import threading
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import numpy as np

from calibproj.simulate.atlas import AtlasLayout
from calibproj.simulate.timeline import ContentKey, content_image

DEFAULT_THREADS = 2


class AtlasStore:
    """Atlases of the contents in use: ``prefetch`` starts building, ``get`` waits,
    ``retain`` forgets the contents no longer needed (flat ones are kept).

    Args:
        sequence: the projection sequence.
        layout: atlas layout shared by all cameras.
        threads: threads drawing patterns and building atlases.
    """

    def __init__(self, sequence: Any, layout: AtlasLayout, threads: int = DEFAULT_THREADS) -> None:
        self.sequence = sequence
        self.layout = layout
        self.lock = threading.Lock()
        self.futures: dict[ContentKey, Future] = {}
        self.pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="atlas")

    def prefetch(self, keys: set[ContentKey]) -> None:
        with self.lock:
            for key in sorted(keys):
                if key not in self.futures:
                    self.futures[key] = self.pool.submit(self._build, key)

    def get(self, key: ContentKey) -> np.ndarray:
        self.prefetch({key})
        with self.lock:
            future = self.futures[key]
        return future.result()

    def retain(self, keys: set[ContentKey]) -> None:
        with self.lock:
            for key in list(self.futures):
                if key not in keys and key[0] != "flat":
                    del self.futures[key]

    def close(self) -> None:
        """Stop the threads; atlases not started are dropped."""
        self.pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> AtlasStore:
        return self

    def __exit__(self, *exc_info: Any) -> None:
        self.close()

    def _build(self, key: ContentKey) -> np.ndarray:
        return self.layout.build(content_image(self.sequence, key))
