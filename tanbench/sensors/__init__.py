"""The vehicle's sensors (Table 1): IMU, DVL velocity and beam ranges, altimeter, pressure."""
