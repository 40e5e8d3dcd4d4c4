"""Reporting: Tables I-III (`tables`), plots and pictures, the HTML report (`html`, `python -m bench.report
ROOT`), the sweep merge callback (`merge`) and the paper-agreement analysis (`agreement`, `placement`).
"""
