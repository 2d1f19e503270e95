"""Pictures of motion: PyVista renders of the skeleton (and plotly figures) shared by the
video export, the app and the notebooks."""
