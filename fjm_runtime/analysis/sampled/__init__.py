"""analysis.sampled"""
