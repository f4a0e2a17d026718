"""Compiler flags shared by vibr's render kernels.

:data:`FASTMATH` is False: IEEE arithmetic. With fast-math (even without FMA contraction)
LLVM compiles a loop into variants that round differently (a vectorised body, a scalar
remainder, specialisations), and which elements take which variant depended on the arrays'
addresses: renders of the same view differed in the last bits from run to run (measured in
docs/reference/errors-and-limits.md, "Bit-identical renders"). With IEEE arithmetic every
element is rounded the same way wherever it lies in memory, and the reductions' partial sums are combined in a fixed order by the kernels
(per-band or per-row partials), so a render is bit-identical from run to run. The images
differ from the fast-math ones by rounding only.
"""

FASTMATH = False
