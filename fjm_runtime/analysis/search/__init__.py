"""analysis.search"""
