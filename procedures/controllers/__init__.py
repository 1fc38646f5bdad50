"""Compensation tables in the formats of motion controllers, and the rule each applies.

One module per controller, each with a writer (a procedures.table.CompTable to the controller's
file(s), validated first, written atomically) and a reader (`load`) that returns an object whose
`applied_mm(position_mm, direction)` is the correction the controller adds to the commanded
position there (mm; +1 = reached while the position increases). A table that cancels the
error e(x) (measured minus commanded, um) gives applied_mm = -e(x)/1000. docs/controllers.md
cites each controller's documentation and states its sign convention.
"""
