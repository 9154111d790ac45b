"""`make gap-bench`: a blind benchmark of `propid gap` on SITL flights (docs/gap-bench.md).

The bench flies propid_sitl with known unmodelled effects, hands the diagnosis tool
only what a flight-test engineer would have (the flight-log v1 CSV with the
measured columns and the vehicle file as described), keeps the truth in a separate
answer key, and scores the tool's verdicts next to a plain least-squares baseline.
"""
