"""Validation helpers: what the model is checked against, kept apart from the API.

* :mod:`~pprender.validation.seed`: the seed paper's closed-form approximations
  (docs/seed-approximation.md).

The explicit microsurface reference is :mod:`pprender.reference`.
"""
