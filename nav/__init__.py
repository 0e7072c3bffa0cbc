"""Flight-style navigation algorithms modelled on the Mars Exploration Rovers.

Pure numpy/scipy/OpenCV: no MuJoCo, no rerun, no simulator imports. Consumes images, camera models, encoder and
IMU samples; returns estimates.
"""
