"""analysis.certificates"""
