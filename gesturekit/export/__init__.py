"""Writers of finished motion: npz archives and BVH files, with the shared atomic file helpers."""
