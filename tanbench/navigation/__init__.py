"""The vehicle's own navigation system (SINS levelling + gyro heading + DVL dead reckoning)."""
