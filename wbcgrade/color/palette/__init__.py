"""The paper's palette mode: the weight fit, the transport map, the smooth map."""
