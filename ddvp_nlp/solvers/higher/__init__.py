"""higher"""
