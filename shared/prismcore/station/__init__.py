"""Station mode: a camera calibrated to the support a part stands on, so a box resting on it is
measured from its silhouette in millimetres, with no click and no known edge.

``board`` describes, draws and finds calibration boards; ``calibrate`` makes a station (camera,
support plane, plate); ``registration`` re-registers a photo on the plate (or finds the camera
unmoved); ``segment`` outlines the part; ``boxfit`` fits the box to the outline (`OutlineFit`);
``hidden_sides`` reads a height the outline lost; ``measure`` chains them and derives the seven points;
``verify`` holds the statistics of a verification with a reference part; ``certify`` what a
measurement states of its station (the verification's status, the camera's drift since
calibration and its cost); ``capability`` the scale over the support and the smallest part and
tolerance it holds.

Its public names are listed once, in `__init__.pyi`, and imported on first use (`lazy_loader`).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
