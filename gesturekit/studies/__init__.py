"""Running a user study on a stimuli folder: its design, the participant server and its response store,
the analysis."""
