"""Writers of finished motion: npz archives, BVH files and MP4 videos with the speech."""
