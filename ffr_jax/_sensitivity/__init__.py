"""Sensitivity methods: the paper's adjoint variable method and its cross-checks."""
