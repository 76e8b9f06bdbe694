"""Code the API and the workers share: settings, job records, the job store, object storage.

Nothing here imports numpy or OpenCV, so the API stays light.
"""
