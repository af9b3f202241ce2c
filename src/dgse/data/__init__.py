"""Training data: rasterized network inputs and targets, symmetry augmentation, datasets."""
