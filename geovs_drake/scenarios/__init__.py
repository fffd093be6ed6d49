"""Scenario files shipped with the package (package data), found with importlib.resources.

* ``suite.yaml``: the scenarios of ``geovs-drake compare``
  (:func:`geovs_drake.scenario.load_suite`).
"""
