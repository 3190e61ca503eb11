"""userio: the plumbing every package shares: user errors, atomic files, validated TOML fields.

A leaf package: it imports nothing of the project, and every package (``bridge``, ``flexure``,
``calibration``, ``estimator``, ``torquebench``) may import it.
"""
