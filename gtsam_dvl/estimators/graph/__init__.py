"""A log as a factor graph: the factors from explicit measurements (factor_maker), the keyframes' IMU motion to
each ping, the whole log's graph (log_graph), the bulk DVL and IMU factors, and the QR solver."""
