"""The tracker's parameters: dataclasses loaded from YAML, validated and resolved once against a
model.
"""
