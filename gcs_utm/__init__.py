"""gcs-utm: a UAS Traffic Management ground service for U-space in-flight services.

Tracking, Monitoring, Emergency Management and Tactical Deconfliction after Capitán et al.
(Appl. Sci. 2021, 11, 3995), connected over MAVLink to PX4 / ArduPilot vehicles.
"""

__version__ = "0.1.0"
