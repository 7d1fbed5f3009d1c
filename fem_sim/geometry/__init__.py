"""Livers: the embedded phantom, imported surfaces, volume meshes and masks, regions, and
the scene-4 population (CPD registration + PCA).
"""
