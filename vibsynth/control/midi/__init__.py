"""control/midi"""
