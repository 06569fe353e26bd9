"""From camera videos to MSM tracks: inputs checked, sync, detection, merging."""
