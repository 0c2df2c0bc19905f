"""march"""
