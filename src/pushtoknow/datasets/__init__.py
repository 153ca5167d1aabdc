"""Datasets: HDF5 shards of simulated pushes, their generation, a torch Dataset, MIT Push."""
