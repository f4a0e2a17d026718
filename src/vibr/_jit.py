"""Compiler flags shared by vibr's numba kernels.

:data:`FASTMATH` is LLVM's fast-math set *without* ``contract`` (fused multiply-add). With
``contract``, a loop's vectorised body and its scalar remainder round ``a·b + c``
differently, and which elements take which path depends on the arrays' addresses: two runs
of the same render differed in the last bit (issue 24). Without it every element is rounded
the same way wherever it lies in memory, so a render is bit-identical from run to run, while
``reassoc`` still lets the reductions vectorise (their per-band partial sums are combined in
a fixed order by the callers).
"""

FASTMATH = {"nnan", "ninf", "nsz", "arcp", "afn", "reassoc"}
