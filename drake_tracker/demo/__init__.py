"""``drake-tracker demo``: simulate a scenario, track it in the Diagram, report and show it in
Meshcat.
"""
