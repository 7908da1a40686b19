"""Datasets: the LeRobotDataset schema, expert collection, mirroring, UMI zarr import/export."""
