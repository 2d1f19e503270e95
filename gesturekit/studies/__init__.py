"""Running a user study on a stimuli folder: its design, the participants' pages, the answers, the analysis."""
