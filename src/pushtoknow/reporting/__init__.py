"""How results are shown to people: display units, markdown tables and reports, figures.

Files and JSON stay SI (docs/DESIGN.md §2); this package converts only for display. It renders
what the evaluation, real-data and identification code return and imports none of them.
"""
