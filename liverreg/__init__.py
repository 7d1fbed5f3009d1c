"""liverreg: a liver placed in a population of livers. Non-rigid CPD of a template onto a
liver, the PCA of the registered population and a new liver's shape coefficients
(:mod:`liverreg.cpd`, :mod:`liverreg.shape_model`). numpy, scipy and data_spec only: the solver
builds the population with it, the trainer's ``predict-liver`` places a new liver with the same
code.
"""
