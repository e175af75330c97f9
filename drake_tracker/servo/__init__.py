"""Closed-loop servo study: the hand servoed to targets in the camera frame, fed by the
encoders alone (a), by drake_tracker (b) or by the truth (c).

Modules: ``config`` (YAML dataclasses), ``world`` (the dynamic plant and its joint
servo), ``feedback`` (the three X_CE sources), ``controller`` (Cartesian law + Drake's
differential IK), ``study`` (build and run one Diagram), ``outcomes`` (per-target errors),
``meshcat_view`` (the recording, targets as triads) and ``report`` (table, plot;
``drake-tracker servo``).
"""
