"""control/osc"""
