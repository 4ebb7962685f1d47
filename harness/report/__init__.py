"""Reports built from a stored campaign run: one self-contained HTML file and a PDF.

``mbh._harness.report.build`` collects a run's data into a template context, ``summary`` makes the
tables, ``seed_compare`` sets the seed's published figures next to ours, ``pdf`` paginates the
same content, and ``figures`` / ``mechanism`` / ``style`` draw the pictures.
"""
