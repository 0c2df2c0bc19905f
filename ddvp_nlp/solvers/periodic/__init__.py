"""periodic"""
