"""The robot process (the paper's "slave"): filters, command pipeline, safety, drivers."""
