"""Answers recalled for exact inputs: fits of one demonstration share the work that does not
depend on what differs between them (the method, the basis count, the constraints)."""

from __future__ import annotations

import numpy as np


def exact(*arrays) -> tuple:
    """Value and memory layout of each array (a product's summation order follows the
    layout), as part of a :class:`Recall` key."""
    values = [np.asarray(array) for array in arrays]
    return tuple((v.dtype.str, v.shape, v.strides, v.flags.aligned, v.tobytes()) for v in values)


class Recall:
    """The answers of the ``size`` distinct keys (exact inputs, :func:`exact`) last asked for.

    An answer (an array or a tuple of arrays) is kept and returned itself, read-only, not a
    copy: its memory layout is kept, and with it the order in which later products sum over
    it (``einsum``, ``@``), so a recalled answer gives the same bits as a new one.
    """

    def __init__(self, size: int):
        self.size = size
        self._answers: dict = {}

    def __call__(self, key, compute):
        """``compute()``, or the answer it gave for ``key``."""
        answers = self._answers
        if key in answers:
            answers[key] = answers.pop(key)  # now the newest
            return answers[key]
        if len(answers) >= self.size:
            del answers[next(iter(answers))]  # the one asked for longest ago
        answer = compute()
        for part in answer if isinstance(answer, tuple) else (answer,):
            part.flags.writeable = False
        answers[key] = answer
        return answer

    def clear(self) -> None:
        """Forget every answer."""
        self._answers.clear()
