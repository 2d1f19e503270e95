"""Running a user study on a stimuli folder: the participant server and its response store (this part)."""
