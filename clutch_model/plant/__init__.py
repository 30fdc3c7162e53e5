"""The plant: parameters, the friction law, mechanisms, the compiled equations and the simulators."""
