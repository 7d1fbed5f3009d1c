"""Datasets: cases drawn from a scene, the MPI batch generator, summaries, the command line."""
