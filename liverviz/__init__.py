"""liverviz: pictures of livers (pyvista, off-screen or in a window), shared by the solver's
summaries and the surrogate's viewer. Needs numpy; pyvista is imported when it first draws.
"""
