"""Scattering orders as tables hold them (docs/conventions.md §2): 1, 2, 3 and 4+, and the rows
after them.

Numbers only: the table reader, ``compare`` and the command line read them without numba.
"""

#: orders tallied separately: 1, 2, 3 and 4+
ORDERS = 4
#: rows of a run's per-incidence BRDF and albedo estimates after the orders: all orders, order
#: 1 scattered by the base (conventions §6, ``brdf_order1_base``), and orders 1 and 2 together
#: (the f2 of Meneveaux et al. 2015, Sec. 3.3, with a standard error of its own:
#: the two orders of a realization are correlated)
RESULT_ALL_ORDERS, RESULT_ORDER1_BASE, RESULT_ORDERS12 = ORDERS, ORDERS + 1, ORDERS + 2
RESULT_ROWS = ORDERS + 3
