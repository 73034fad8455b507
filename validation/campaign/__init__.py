"""Drop-test calibration campaign (issue 5): formulas, signal metrics, studies, calibration.

Modules
-------
``formulas``     empirical rockfall-cushion impact-force formulas (Japan, ASTRA, Labiouse)
``signals``      impact metrics of a drop-mass record and the double-peak detector
``studies``      the campaign runs, comparison table, plots, domain- and particle-size studies
``calibration``  target set, objective, coarse design + Nelder-Mead, soil-card I/O
"""
